"""Writing a model card into an ONNX file and sealing it.

The seal is what the runtime verifies at load: the sha256 of the graph and weights (computed by
the runtime's own ``graph_digest``, over everything but the metadata), the self-test's answer
(recorded by running the very file in onnxruntime) and ``bsn.card_sha256`` over the card.
"""

from __future__ import annotations

from pathlib import Path

import onnx

from bsn_edge.card import DigestVersion, ModelCard
from bsn_edge.modelfile import selftest
from bsn_edge.modelfile.read import ModelFile, graph_digest, session
from bsn_edge.sequence.images import atomic_write_bytes


def set_metadata(model: onnx.ModelProto, card: ModelCard) -> None:
    """Replace the model's ``metadata_props`` with ``card``'s entries."""
    del model.metadata_props[:]
    for k, v in card.to_metadata().items():
        e = model.metadata_props.add()
        e.key, e.value = k, v


def seal(path: str | Path, card: ModelCard, out: str | Path | None = None) -> ModelCard:
    """Seal the model at ``path`` with ``card`` (written to ``out``, default in place); returns
    the sealed card. The unsealed card's own seal fields are ignored and recomputed."""
    path = Path(path)
    model = onnx.load(str(path))
    del model.metadata_props[:]
    data = model.SerializeToString()
    digest = graph_digest(data)
    sess = session(data)

    def infer(frame):
        p, d = sess.run(None, {"frame": frame[None]})
        return p[0, 0], d[0, 0]

    sealed = card.replace(graph_sha256=digest,
                          self_test=selftest.record(infer, card.input_size, card.quantization))
    set_metadata(model, sealed)
    data = model.SerializeToString()
    if graph_digest(data) != digest:   # the serializer must not reorder the graph's bytes
        raise RuntimeError("the model's bytes changed while writing its metadata; cannot seal it")
    atomic_write_bytes(Path(out) if out is not None else path, data)
    return sealed


def read_card(path: str | Path, digests: tuple[DigestVersion, ...] = (DigestVersion.V2,)) -> ModelCard:
    """The card of an exported model (validated), read as the runtime reads it; ``digests``: the card
    digests accepted (a model sealed before the canonical one is read only to be resealed)."""
    return ModelCard.from_metadata(ModelFile.read(path).metadata, str(path), digests)
