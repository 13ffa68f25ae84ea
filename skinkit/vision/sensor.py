"""Image formation after the optics: blur, illumination falloff, noise, quantisation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from skinkit.vision import VisionError


@dataclass(frozen=True)
class Sensor:
    """A camera sensor and lens blur.

    Attributes:
        blur_px: standard deviation of the Gaussian lens blur [px] (0: none).
        noise: standard deviation of additive Gaussian read noise, fraction of full scale [1].
        bits: quantisation depth (8 or 16) [bit].
        falloff: relative illumination loss at the image corner (cos^4-like radial law) [1].
        gain: full-scale fraction reached by radiance 1 [1].
    """

    blur_px: float = 0.6
    noise: float = 0.01
    bits: int = 8
    falloff: float = 0.0
    gain: float = 1.0

    def expose(self, radiance: np.ndarray, rng: np.random.Generator | int | None) -> np.ndarray:
        """Turn a ``(H, W)`` radiance map [0..1] into a quantised image (uint8 or uint16).

        ``rng``: a Generator or seed for the noise (None only when ``noise == 0``).
        """
        if self.bits not in (8, 16):
            raise VisionError(f"Sensor.bits must be 8 or 16, got {self.bits}")
        img = np.asarray(radiance, dtype=float) * self.gain
        if self.blur_px > 0:
            img = gaussian_filter(img, self.blur_px, mode="nearest")
        if self.falloff > 0:
            h, w = img.shape
            y, x = np.mgrid[0:h, 0:w]
            r2 = ((x - (w - 1) / 2) ** 2 + (y - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
            img = img * (1.0 - self.falloff * r2)
        if self.noise > 0:
            if rng is None:
                raise VisionError("Sensor.expose needs a seed or Generator when noise > 0")
            gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
            img = img + gen.normal(0.0, self.noise, img.shape)
        full = float(2**self.bits - 1)
        out = np.clip(np.rint(img * full), 0, full)
        return out.astype(np.uint8 if self.bits == 8 else np.uint16)
