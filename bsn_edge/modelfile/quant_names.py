"""The names of int8 quantization's choices, importable without onnxruntime's quantization tools (a CLI's
``--help`` reads them); :mod:`bsn_edge.export.quantize` maps each to onnxruntime's value."""

METHOD_NAMES: tuple[str, ...] = ("entropy", "minmax", "percentile")
TYPE_NAMES: tuple[str, ...] = ("int8", "uint8")
