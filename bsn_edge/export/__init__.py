"""Torch -> ONNX export of the fused depth + blind-spot model, its int8 quantization and its seal."""

from bsn_edge.export.fused import FusedModel, check_parity, to_onnx
from bsn_edge.export.quantize import QuantConfig, head_nodes, quantize
from bsn_edge.export.seal import read_card, seal

__all__ = ["FusedModel", "QuantConfig", "check_parity", "head_nodes", "quantize", "read_card", "seal", "to_onnx"]
