"""An ONNX model file as the runtime sees it: bytes read once, metadata, integrity digest, session.

No ``onnx`` package: the file is a protobuf ``ModelProto`` whose top-level fields are walked
here (wire format only). ``graph_sha256`` is the sha256 of every top-level field except
``metadata_props`` (field 14), in file order: the graph, its weights, opsets and producer, so
the digest can be stored inside the file's own metadata. The export computes it with this same
code. The runtime reads the file once: the bytes it hashed and verified are the bytes onnxruntime
builds its session from.
"""

from __future__ import annotations

import hashlib
import io
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from bsn_edge.user_file import read_user_file

METADATA_FIELD = 14          # ModelProto.metadata_props
CHUNK = 1 << 20
ENTRY_KEY, ENTRY_VALUE = 1, 2  # StringStringEntryProto


def _read_varint(f: BinaryIO) -> int | None:
    """The next varint, or None at the end of the stream."""
    shift = value = 0
    while True:
        b = f.read(1)
        if not b:
            if shift:
                raise ValueError("truncated varint")
            return None
        value |= (b[0] & 0x7F) << shift
        if b[0] < 0x80:
            return value
        shift += 7
        if shift > 63:
            raise ValueError("varint too long")


def _fields(f: BinaryIO, size: int) -> Iterator[tuple[int, int, int, int]]:
    """(field number, start of the field's bytes, start of its value, end) of each top-level field
    of the protobuf message in ``f``; the caller may read within a field, the walk seeks past it."""
    while True:
        start = f.tell()
        tag = _read_varint(f)
        if tag is None:
            return
        number, wire = tag >> 3, tag & 7
        if wire == 0:
            _read_varint(f)
            value, end = start, f.tell()
        elif wire in (1, 5):
            value = f.tell()
            end = value + (8 if wire == 1 else 4)
        elif wire == 2:
            n = _read_varint(f)
            if n is None:
                raise ValueError(f"truncated field at byte {start}")
            value = f.tell()
            end = value + n
        else:
            raise ValueError(f"unsupported protobuf wire type {wire} at byte {start}")
        if end > size or number == 0:
            raise ValueError(f"truncated or malformed protobuf field at byte {start}")
        yield number, start, value, end
        f.seek(end)


def _scan(f: BinaryIO, size: int) -> tuple[dict[str, str], str]:
    """Metadata and graph digest of a serialized model, read in chunks (the weights never sit in
    memory at once)."""
    h = hashlib.sha256()
    metadata: dict[str, str] = {}
    for number, start, value, end in _fields(f, size):
        if number == METADATA_FIELD:
            f.seek(value)
            entry = f.read(end - value)
            kv = {}
            for n, _, s, e in _fields(io.BytesIO(entry), len(entry)):
                if n in (ENTRY_KEY, ENTRY_VALUE):
                    kv[n] = entry[s:e].decode("utf-8", errors="replace")
            key = kv.get(ENTRY_KEY, "")
            if key in metadata:
                # a second entry under one key: tools that list metadata would show both, and which of
                # them the card stands for would depend on the reader
                raise ValueError(f"its metadata holds the key {key!r} twice")
            metadata[key] = kv.get(ENTRY_VALUE, "")
            continue
        f.seek(start)
        left = end - start
        while left:
            chunk = f.read(min(left, CHUNK))
            if not chunk:
                raise ValueError(f"truncated field at byte {start}")
            h.update(chunk)
            left -= len(chunk)
    return metadata, h.hexdigest()


def graph_digest(data: bytes) -> str:
    """sha256 of serialized model bytes without ``metadata_props``."""
    return _scan(io.BytesIO(data), len(data))[1]


@dataclass(frozen=True)
class ModelFile:
    """A model file's bytes, read once, with their metadata and the digest of everything else.

    The session is built from ``data``, the bytes that were hashed and verified, never from the
    path again: a file replaced after the check cannot be the one that runs."""

    path: Path
    metadata: dict[str, str]
    graph_sha256: str
    data: bytes = field(default=b"", repr=False, compare=False)

    @classmethod
    def read(cls, path: str | Path) -> ModelFile:
        p = Path(path)
        if not p.exists():
            raise FileNotFoundError(f"model {p} not found")
        data = read_user_file(p, "model")     # a FIFO, a device or a model over its budget: refused unread
        try:
            metadata, digest = _scan(io.BytesIO(data), len(data))
        except ValueError as e:
            raise ValueError(f"{p}: not an ONNX model file ({e})") from None
        return cls(p, metadata, digest, data)


# what onnxruntime says when its exact x86 kernels (session.x64quantprecision) meet signed activations
EXACT_KERNELS_REFUSED = "Attempt to replace the existing tensor"


def _options(threads: int, spinning: bool, profile_prefix: str | None, exact_x64: bool):
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    # no arena and no pre-planned memory pattern: less peak memory on the car for the same speed
    so.enable_cpu_mem_arena = False
    so.enable_mem_pattern = False
    if not spinning:
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    # x86 CPUs without VNNI (AVX2, AVX-512F) multiply uint8 activations by int8 weights in pairs
    # summed into int16, which saturates for weights outside [-64, 63] (7-bit weights stay clear of
    # it). This makes onnxruntime use uint8 x uint8 there (exact, slower); on VNNI and ARM CPUs it
    # changes nothing.
    if exact_x64:
        so.add_session_config_entry("session.x64quantprecision", "1")
    if profile_prefix:
        so.enable_profiling, so.profile_file_prefix = True, profile_prefix
    return so


def session(model: str | Path | bytes, threads: int = 2, spinning: bool = True,
            profile_prefix: str | None = None, exact_x64: bool = True):
    """An onnxruntime CPU session with ``threads`` intra-op threads on a path or model bytes
    (profiling into files starting with ``profile_prefix`` when given). ``exact_x64``: onnxruntime's
    exact uint8 x uint8 kernels on x86 CPUs without VNNI, which 8-bit weights need there; a model
    with 7-bit weights (:attr:`~bsn_edge.card.ModelCard.seven_bit_weights`) is exact on the faster
    uint8 x int8 kernels and can do without."""
    import onnxruntime as ort

    if not exact_x64:
        return ort.InferenceSession(model if isinstance(model, bytes) else str(model),
                                    _options(threads, spinning, profile_prefix, exact_x64=False),
                                    providers=["CPUExecutionProvider"])
    so = _options(threads, spinning, profile_prefix, exact_x64=True)
    src = model if isinstance(model, bytes) else str(model)
    try:
        return ort.InferenceSession(src, so, providers=["CPUExecutionProvider"])
    except Exception as e:
        if EXACT_KERNELS_REFUSED not in str(e):
            raise
    # onnxruntime cannot give a model with signed int8 activations its exact kernels: it runs as
    # quantized, exact where its weights fit in 7 bits or the CPU has VNNI; the self-test checks it
    warnings.warn(f"{'the model' if isinstance(model, bytes) else model}: onnxruntime's exact uint8 x uint8 kernels do "
                  "not take signed int8 activations; on x86 CPUs without VNNI such a model is exact only with 7-bit "
                  "weights (bsn-export --weight-bits 7, the default)", RuntimeWarning, stacklevel=2)
    so = _options(threads, spinning, profile_prefix, exact_x64=False)
    return ort.InferenceSession(src, so, providers=["CPUExecutionProvider"])
