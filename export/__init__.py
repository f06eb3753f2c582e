"""Torch -> ONNX export of the fused depth + blind-spot model and its int8 quantization."""
