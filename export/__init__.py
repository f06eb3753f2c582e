"""Torch -> ONNX export of the fused depth + blind-spot model and its int8 quantization."""

from bsn_edge.export.fused import FusedModel, check_parity, session, to_onnx
from bsn_edge.export.quantize import QuantConfig, head_nodes, quantize

__all__ = ["FusedModel", "QuantConfig", "check_parity", "head_nodes", "quantize", "session", "to_onnx"]
