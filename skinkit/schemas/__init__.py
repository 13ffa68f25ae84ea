"""Typed, validated records in SI units. Constructors check shapes and units and name the field."""

from skinkit.schemas.camera import CameraModel, CameraRig
from skinkit.schemas.images import ImageSequence
from skinkit.schemas.observations import (
    Channel,
    ChannelPrediction,
    Observations,
    Prediction,
    ProtocolObservations,
)
from skinkit.schemas.parameters import Parameter, ParameterSet
from skinkit.schemas.protocol import Protocol
from skinkit.schemas.results import EffectScore, FitResult, GapReport
from skinkit.schemas.robot import RobotRecord
from skinkit.schemas.surface import SurfaceProfile, SurfaceTrack

__all__ = [
    "CameraModel",
    "CameraRig",
    "Channel",
    "ChannelPrediction",
    "EffectScore",
    "FitResult",
    "GapReport",
    "ImageSequence",
    "Observations",
    "Parameter",
    "ParameterSet",
    "Prediction",
    "Protocol",
    "ProtocolObservations",
    "RobotRecord",
    "SurfaceProfile",
    "SurfaceTrack",
]
