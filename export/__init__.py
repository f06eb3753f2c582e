"""Torch -> ONNX export of the fused depth + blind-spot model and its int8 quantization."""

from bsn_edge.export.fused import FusedModel, check_parity, session, to_onnx

__all__ = ["FusedModel", "check_parity", "session", "to_onnx"]
