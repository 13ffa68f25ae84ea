"""``sim``: the device model in this process, stepped as fast as the host asks for data."""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit_hardware.device import Device, Event, Injection
from skinkit_hardware.host import HostDriver
from skinkit_hardware.skin import make_skin


class SimTransport:
    """Commands are method calls; each ``receive`` advances the device by ``block_s``."""

    def __init__(self, device: Device, block_s: float = 0.05) -> None:
        self.device = device
        self.block_ticks = max(1, int(round(block_s * device.params.control_rate_hz)))
        self.stats: dict[str, Any] = {}

    def send(self, command: str, **args: Any) -> None:
        """Carry out one host ``command`` on the simulated device."""
        d = self.device
        if command == "load":
            d.load(args["mode"], args["rate_hz"], args["setpoints"], args.get("trigger_period_s", 0.0))
        elif command == "configure":
            d.configure(**args)
        else:
            getattr(d, command)(**args)

    def receive(self, timeout_s: float) -> tuple[np.ndarray, list[Event]]:
        """Advance the simulated device one block: ``(samples (n, 15), events)``; ``timeout_s`` is unused."""
        d = self.device
        d.heartbeat()
        d.advance(self.block_ticks)
        return d.drain(), d.take_events()

    def close(self) -> None:
        """Disable the simulated device's motors."""
        self.device.disable()


class SimDriver(HostDriver):
    """In-process simulated robot. ``connect(skin="kelvin-voigt"|"wiener"|..., seed=0,
    device=Device(...))``; faster than real time."""

    name = "sim"

    def _open(self, **options: Any) -> SimTransport:
        device = options.pop("device", None)
        if device is None:
            device = Device(
                params=self.params,
                limits=self.limits,
                geometry=self.geometry,
                skin=make_skin(options.pop("skin", "kelvin-voigt")),
                seed=int(options.pop("seed", 0)),
                injection=options.pop("injection", None) or Injection(),
                decimation=self.decimation,
            )
        block_s = float(options.pop("block_s", 0.05))
        if options:
            from skinkit.errors import OptionError

            raise OptionError(f"sim driver: unknown option(s) {sorted(options)}")
        return SimTransport(device, block_s)
