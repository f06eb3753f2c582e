"""Networks in plain torch: ResNet encoders, DeepLabV3+, U-Net, D, B and the registry."""

from bsn_edge.models.bsn import BlindSpotNet, DepthNet, depth_feature
from bsn_edge.models.registry import MODELS, ModelSpec, build, create_model, create_teacher, get_spec

__all__ = ["MODELS", "BlindSpotNet", "DepthNet", "ModelSpec", "build", "create_model", "create_teacher",
           "depth_feature", "get_spec"]
