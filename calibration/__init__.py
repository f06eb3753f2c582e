"""Camera intrinsics and quantization calibration sets."""
