"""The inference engine: one verified model file, one onnxruntime session, its model card.

At load, in this order, any failure raising :class:`ModelError` (the runtime then refuses to
start): the file is read in chunks; its model card is read and validated; the digest of the
graph and weights is compared with the card's; with trusted keys, the signature over both
digests is checked against a :class:`~bsn_edge.modelfile.trust.TrustPolicy`; the session is built from the file; its
input and outputs are checked against the card; the self-test frame is run and compared with the
answer stored at export.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.card import CARD_SHA_KEY, ModelCard
from bsn_edge.modelfile import selftest
from bsn_edge.modelfile.read import ModelFile, session
from bsn_edge.modelfile.trust import TrustPolicy, UntrustedModelError, Verdict


class ModelError(ValueError):
    """The model cannot be trusted or run: the runtime must not start on it."""


class Engine:
    """Runs the model on its preallocated input buffer ``buf`` (the loop warps frames into it)."""

    def __init__(self, model: str | Path, threads: int = 2, spinning: bool = False,
                 trust: TrustPolicy | Mapping[str, Any] | None = None, threshold: float | None = None) -> None:
        """``trust``: the policy (or public keys by id, allowing nothing else) the model's signature is
        checked against; a model it does not allow is refused. ``verdict`` says which trusted key signed
        it ("" when none did: ``authentic`` is then False). Without ``trust`` the signature is not checked
        and the model counts as not authentic (``bsn-run`` always checks). ``spinning``:
        onnxruntime's idle threads spin-wait for the next work; off by default, because between two
        inferences the loop decodes, warps and calibrates on the same cores, which spinning threads
        take from it (``benchmarks/results/runtime.md``). ``threshold``: decide at
        this probability instead of the card's (a benchmark reading a model's operating points; ``bsn-run``
        decides at the card's)."""
        if threshold is not None and not 0 < threshold < 1:
            raise ValueError(f"a decision threshold is a probability in (0, 1), got {threshold}")
        self.path = Path(model)
        mf = ModelFile.read(self.path)   # FileNotFoundError / ValueError name the file
        self.card = self._sealed_card(mf)
        self.threshold: float = self.card.threshold if threshold is None else threshold  # type: ignore[assignment]
        self.verdict = Verdict("", "the signature was not checked")
        if trust is not None:
            policy = trust if isinstance(trust, TrustPolicy) else TrustPolicy(trust)
            try:
                self.verdict = policy.check(mf.metadata, mf.graph_sha256, mf.metadata.get(CARD_SHA_KEY, ""),
                                            str(self.path))
            except UntrustedModelError as e:
                raise ModelError(str(e)) from None
        try:
            # 7-bit weights are exact on every x86 CPU's fast kernels; 8-bit ones need the exact ones
            # from the bytes that were verified, not the path: the file may have changed since
            self.sess = session(mf.data, threads, spinning, exact_x64=not self.card.seven_bit_weights)
        except Exception as e:
            raise ModelError(f"{self.path}: onnxruntime cannot load it: {e}") from None
        self._check_io()
        h, w = self.card.input_size
        self.buf = np.empty((1, h, w, 3), np.uint8)
        expected = self.card.self_test
        assert expected is not None     # a sealed card has its answer (checked above)
        try:
            self.self_test = selftest.check(lambda f: self.infer(f[None]), self.card.input_size, expected)
        except selftest.SelfTestError as e:
            raise ModelError(f"{self.path}: {e}") from None

    def _sealed_card(self, mf: ModelFile) -> ModelCard:
        """The card of the model file ``mf``: sealed, with a threshold, and the graph the one it was sealed with;
        :class:`ModelError` naming the file otherwise."""
        try:
            card = ModelCard.from_metadata(mf.metadata, str(self.path))
        except ValueError as e:
            raise ModelError(str(e)) from None
        if not card.sealed:
            raise ModelError(f"{self.path}: the model carries no integrity digest or self-test answer (exported "
                             f"before models were sealed); seal a copy you trust with: bsn-export --reseal "
                             f"{self.path} --out SEALED.onnx")
        if card.threshold is None:
            raise ModelError(f"{self.path}: the model's card has no decision threshold (its training chose none)")
        if mf.graph_sha256 != card.graph_sha256:
            raise ModelError(f"{self.path}: the model file is damaged: the sha256 of its graph and weights "
                             f"({mf.graph_sha256[:12]}...) is not the one its export recorded "
                             f"({card.graph_sha256[:12]}...)")
        return card

    def _check_io(self) -> None:
        h, w = self.card.input_size
        ins, outs = self.sess.get_inputs(), self.sess.get_outputs()
        if [i.name for i in ins] != ["frame"] or [o.name for o in outs] != ["blindspot", "depth"]:
            raise ModelError(f"{self.path}: graph has inputs {[i.name for i in ins]} and outputs "
                             f"{[o.name for o in outs]}; a bsn-export model has 'frame' -> 'blindspot', 'depth'")
        shape, kind = list(ins[0].shape), ins[0].type
        if shape != [1, h, w, 3] or kind != "tensor(uint8)":
            raise ModelError(f"{self.path}: the graph takes {kind} {shape}, its card says uint8 [1, {h}, {w}, 3] "
                             f"(input size {h}x{w})")
        for o in outs:
            if list(o.shape) != [1, 1, h, w] or o.type != "tensor(float)":
                raise ModelError(f"{self.path}: output {o.name!r} is {o.type} {list(o.shape)}; a bsn-export model "
                                 f"gives float [1, 1, {h}, {w}] (the card's input size)")

    @property
    def signer(self) -> str:
        """The id of the trusted key that signed the model, "" when none did (or it was not checked)."""
        return self.verdict.signer

    @property
    def authentic(self) -> bool:
        return self.verdict.authentic

    @property
    def kernels(self) -> str:
        """Which onnxruntime kernels the model runs on, as the summary says it."""
        if self.card.float_graph:
            return "fp32"
        if self.card.seven_bit_weights:
            return "int8: uint8 x int8 (7-bit weights, exact on every x86 CPU)"
        return "int8: exact uint8 x uint8 on x86 CPUs without VNNI"

    @property
    def size(self) -> tuple[int, int]:
        """(H, W) the model runs at."""
        return self.card.input_size

    def infer(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        prob, depth = self.sess.run(None, {"frame": batch})
        if prob.shape != (1, 1, *self.card.input_size) or depth.shape != prob.shape:
            # a graph with symbolic dimensions can still answer in another shape at run time
            raise ModelError(f"{self.path}: the graph answered {list(prob.shape)} and {list(depth.shape)}, not "
                             f"[1, 1, {self.card.input_size[0]}, {self.card.input_size[1]}]")
        return prob[0, 0], depth[0, 0]

    def warmup(self, n: int = 3) -> None:
        for _ in range(n):
            self.infer(np.zeros_like(self.buf))
