"""Networks in plain torch: ResNet encoders, DeepLabV3+, U-Net, D, B and the registry."""

from bsn_edge.networks.bsn import MAX_DEPTH_M, MIN_DEPTH_M, ORACLE_DEPTH_NOTE, BlindSpotNet, DepthNet, depth_feature
from bsn_edge.networks.registry import (
    MODELS,
    TEACHER_ENCODERS,
    Carried,
    ModelSpec,
    build,
    carried_over,
    create_model,
    create_teacher,
    describe,
    get_spec,
    start_from,
    teacher_encoder,
    weights_bytes,
)

__all__ = [
    "MAX_DEPTH_M",
    "MIN_DEPTH_M",
    "MODELS",
    "ORACLE_DEPTH_NOTE",
    "TEACHER_ENCODERS",
    "BlindSpotNet",
    "Carried",
    "DepthNet",
    "ModelSpec",
    "build",
    "carried_over",
    "create_model",
    "create_teacher",
    "depth_feature",
    "describe",
    "get_spec",
    "start_from",
    "teacher_encoder",
    "weights_bytes",
]
