"""An ONNX model file as the runtime sees it: bytes read once, metadata, integrity digest, session.

No ``onnx`` package: the file is a protobuf ``ModelProto`` whose top-level fields are walked
here (wire format only). ``graph_sha256`` is the sha256 of every top-level field except
``metadata_props`` (field 14), in file order: the graph, its weights, opsets and producer, so
the digest can be stored inside the file's own metadata. The export computes it with this same
function, and the runtime loads the session from the very bytes it verified.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

METADATA_FIELD = 14          # ModelProto.metadata_props
ENTRY_KEY, ENTRY_VALUE = 1, 2  # StringStringEntryProto


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        if i >= len(buf):
            raise ValueError("truncated varint")
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, i
        shift += 7
        if shift > 63:
            raise ValueError("varint too long")


def _fields(buf: bytes) -> Iterator[tuple[int, int, int, int]]:
    """(field number, start of the field's bytes, start of its value, end) of each top-level field."""
    i = 0
    while i < len(buf):
        start = i
        tag, i = _varint(buf, i)
        number, wire = tag >> 3, tag & 7
        if wire == 0:
            _, end = _varint(buf, i)
        elif wire == 1:
            end = i + 8
        elif wire == 2:
            n, i = _varint(buf, i)
            end = i + n
        elif wire == 5:
            end = i + 4
        else:
            raise ValueError(f"unsupported protobuf wire type {wire} at byte {start}")
        if end > len(buf) or number == 0:
            raise ValueError(f"truncated or malformed protobuf field at byte {start}")
        yield number, start, i, end
        i = end


def graph_digest(data: bytes) -> str:
    """sha256 of the model bytes without ``metadata_props``."""
    h = hashlib.sha256()
    for number, start, _, end in _fields(data):
        if number != METADATA_FIELD:
            h.update(data[start:end])
    return h.hexdigest()


def read_metadata(data: bytes) -> dict[str, str]:
    """``metadata_props`` of serialized model bytes."""
    out: dict[str, str] = {}
    for number, _, vstart, end in _fields(data):
        if number != METADATA_FIELD:
            continue
        entry = data[vstart:end]
        kv = {}
        for n, _, s, e in _fields(entry):
            if n in (ENTRY_KEY, ENTRY_VALUE):
                kv[n] = entry[s:e].decode("utf-8", errors="replace")
        out[kv.get(ENTRY_KEY, "")] = kv.get(ENTRY_VALUE, "")
    return out


@dataclass(frozen=True)
class ModelFile:
    """A model file's bytes (read once), its metadata and the digest of everything else."""

    path: Path
    data: bytes
    metadata: dict[str, str]
    graph_sha256: str

    @classmethod
    def read(cls, path: str | Path) -> ModelFile:
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"model {p} not found")
        data = p.read_bytes()
        try:
            return cls(p, data, read_metadata(data), graph_digest(data))
        except ValueError as e:
            raise ValueError(f"{p}: not an ONNX model file ({e})") from None


def session(model: str | Path | bytes, threads: int = 2, spinning: bool = True,
            profile_prefix: str | None = None):
    """An onnxruntime CPU session with ``threads`` intra-op threads on a path or model bytes
    (profiling into files starting with ``profile_prefix`` when given)."""
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    if not spinning:
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if profile_prefix:
        so.enable_profiling, so.profile_file_prefix = True, profile_prefix
    src = model if isinstance(model, bytes) else str(model)
    return ort.InferenceSession(src, so, providers=["CPUExecutionProvider"])
