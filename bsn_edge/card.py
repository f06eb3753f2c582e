"""The model card: one typed record of what a model is, and the only code that writes or reads it.

A card travels in two places, written and read here alone: a training run's ``checkpoint.json``
(under ``"card"``) and an exported model's ONNX ``metadata_props`` (one ``bsn.<field>`` entry per
field, JSON-encoded, so a model viewer shows them). Trainer, evaluator, export, quantizer, runtime
and benchmarks take model facts from a card, never from defaults of their own.

Reading validates: a missing or bad key raises ``ValueError`` naming the key and the file.
An exported card is *sealed*: it carries the sha256 of the graph and its weights
(``graph_sha256``), a known-answer self-test, and ``card_sha256`` over every other entry, so a
flipped byte anywhere in the file is caught at load. The digest reads each entry's key and value
with their lengths before them (:func:`card_digest`), so no two cards share one, and a sealed card
is read only when its entries are exactly the card's fields, each one strict JSON.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from bsn_edge.camera import Intrinsics
from bsn_edge.card_records import PRECISION_BF16, PRECISION_FP32, PRECISIONS, UNRECORDED, SelfTest, TrainingRecord
from bsn_edge.mounting import REFERENCE_HEIGHT_M, Mounting

__all__ = ["CARD_SHA_KEY", "EARLY_MOUNTING", "FP32", "PRECISIONS", "PRECISION_BF16", "PRECISION_FP32",
           "SEVEN_BIT_WEIGHTS", "UNCHOSEN_THRESHOLD", "UNRECORDED", "DigestVersion", "ModelCard", "SelfTest",
           "TrainingRecord", "card_digest", "is_float_scheme"]

CARD_VERSION = 1
MODEL_NAME = "BlindSpotNet"
PREFIX = "bsn."
CARD_SHA_KEY = f"{PREFIX}card_sha256"
FP32 = "none (fp32)"
# what the cards of fp32 exports said while the name above was shadowed by the training precision's ("fp32")
_FP32_AS_SEALED_BEFORE = "fp32"
SEVEN_BIT_WEIGHTS = "(7-bit range)"      # how a quantization scheme says its int8 weights lie in [-64, 63]
# used only when a run has no validation clips to choose the threshold on (the trainer says so)
UNCHOSEN_THRESHOLD = 0.5
_HEX64 = re.compile(r"[0-9a-f]{64}")
# A card without a mounting was trained in the fixed-camera world (bsn-synth --camera fixed): cameras at
# the reference height, pitched 0-3 degrees down (1.5 on average), no yaw or roll.
EARLY_MOUNTING = Mounting(height_m=REFERENCE_HEIGHT_M, pitch_deg=1.5)


class DigestVersion(IntEnum):
    """How ``card_sha256`` encodes the entries. V1 joined keys and values with NUL, which two different
    cards could share (one entry's key and value made to carry another's); V2 is canonical."""

    V1 = 1
    V2 = 2


_DIGEST_DOMAIN = b"bsn-edge model card v2\0"


def is_float_scheme(quantization: str) -> bool:
    """Whether a card's ``quantization`` says the graph computes in float (an fp32 export), so its
    self-test holds to fp32's tolerance, not int8's. Cards sealed while ``FP32`` was shadowed said
    ``fp32``; they are float graphs too. What a later step adds after a comma (the integer input's
    upgrade) does not change the arithmetic of the weights."""
    return quantization.split(",")[0].strip() in (FP32, _FP32_AS_SEALED_BEFORE)


# the entries of a card (``ModelCard.to_dict``; ``training`` only when recorded), and those a card read
# from a run's checkpoint.json or a model sealed before they existed may lack
CARD_FIELDS = ("card_version", "model", "variant", "spec", "input_size", "threshold", "camera", "depth_range",
               "quantization", "config_digest", "weights_sha256", "train_camera", "graph_sha256", "self_test",
               "mounting", "training")
OPTIONAL_FIELDS = ("train_camera", "self_test", "config_digest", "graph_sha256", "mounting", "training")


@dataclass(frozen=True)
class ModelCard:
    """What a model is.

    variant:        registry name (``bsn_edge.networks.create_model``), e.g. ``small-light``
    spec:           the architecture record the registry builds it from
    input_size:     (H, W) the model runs at
    threshold:      decision threshold on the blind-spot probability, chosen on validation
                    (``None`` until training has chosen it)
    camera:         the model camera: pinhole intrinsics at ``input_size``
    mounting:       the model camera's reference height above the road and pitch (zero yaw and
                    roll: it looks along the car); every user camera is warped into this camera
    depth_range:    (min, max) metres the depth head can report
    quantization:   scheme of the weights and activations (``none (fp32)`` or the int8 scheme)
    config_digest:  digest of the resolved training config
    weights_sha256: sha256 of the trained weights it came from
    train_camera:   the training clips' camera at its own size (``None`` if unknown)
    training:       how it was trained (:class:`TrainingRecord`; ``None`` if unknown)
    graph_sha256, self_test: the seal of an exported model (empty / ``None`` in a checkpoint)
    """

    variant: str
    spec: Mapping[str, Any]
    input_size: tuple[int, int]
    threshold: float | None
    camera: Intrinsics
    depth_range: tuple[float, float]
    weights_sha256: str
    config_digest: str = ""
    quantization: str = FP32
    train_camera: Intrinsics | None = None
    graph_sha256: str = ""
    self_test: SelfTest | None = field(default=None, repr=False)
    mounting: Mounting = EARLY_MOUNTING
    training: TrainingRecord | None = None

    def __post_init__(self) -> None:
        if not self.variant or not isinstance(self.variant, str):
            raise ValueError("variant must be a model name")
        h, w = self.input_size
        if not (isinstance(h, int) and isinstance(w, int) and h >= 16 and w >= 16):
            raise ValueError(f"input_size must be two integers >= 16 (H, W), got {self.input_size}")
        if self.threshold is not None and not (math.isfinite(self.threshold) and 0.0 < self.threshold < 1.0):
            raise ValueError(f"threshold must lie in (0, 1), got {self.threshold}")
        if (self.camera.height, self.camera.width) != (h, w):
            raise ValueError(f"camera is for {self.camera.height}x{self.camera.width}, the model runs at {h}x{w}")
        lo, hi = self.depth_range
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
            raise ValueError(f"depth_range must be 0 < min < max metres, got {self.depth_range}")
        if not _HEX64.fullmatch(self.weights_sha256):
            raise ValueError(f"weights_sha256 must be 64 hex digits, got {self.weights_sha256!r}")
        if self.graph_sha256 and not _HEX64.fullmatch(self.graph_sha256):
            raise ValueError(f"graph_sha256 must be 64 hex digits, got {self.graph_sha256!r}")
        if self.mounting.yaw_deg != 0.0 or self.mounting.roll_deg != 0.0:
            raise ValueError(f"the model camera looks along the car (zero yaw and roll), got {self.mounting}")

    @property
    def horizon_row(self) -> float:
        """Row of the level horizon in the model camera at ``input_size``."""
        return self.mounting.horizon_row(self.camera)

    # -- derived -------------------------------------------------------------------------------

    @property
    def sealed(self) -> bool:
        return bool(self.graph_sha256) and self.self_test is not None

    @property
    def float_graph(self) -> bool:
        """Whether the graph computes in float (an fp32 export): :func:`is_float_scheme` of its scheme."""
        return is_float_scheme(self.quantization)

    @property
    def seven_bit_weights(self) -> bool:
        """int8 weights within [-64, 63]: x86 CPUs without VNNI multiply them by uint8 activations on
        their fast kernels without saturating, so the model needs no exact uint8 x uint8 kernels."""
        return SEVEN_BIT_WEIGHTS in self.quantization

    def replace(self, **changes: Any) -> ModelCard:
        return dataclasses.replace(self, **changes)

    def at_size(self, height: int, width: int) -> ModelCard:
        """The same model run at another input size (the model camera rescaled with it)."""
        return self.replace(input_size=(int(height), int(width)), camera=self.camera.scaled(width, height))

    # -- checkpoint.json -----------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        d = {
            "card_version": CARD_VERSION, "model": MODEL_NAME, "variant": self.variant, "spec": dict(self.spec),
            "input_size": list(self.input_size), "threshold": self.threshold, "camera": self.camera.to_dict(),
            "depth_range": list(self.depth_range), "quantization": self.quantization,
            "config_digest": self.config_digest, "weights_sha256": self.weights_sha256,
            "train_camera": None if self.train_camera is None else self.train_camera.to_dict(),
            "graph_sha256": self.graph_sha256,
            "self_test": None if self.self_test is None else dataclasses.asdict(self.self_test),
            "mounting": self.mounting.to_dict(),
        }
        if self.training is not None:       # absent, not null: cards from before it read and digest as they did
            d["training"] = self.training.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "model card") -> ModelCard:
        """Validate and build; ``ValueError`` names the missing or bad key and ``where``."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{where}: the model card must be a JSON object")
        version = d.get("card_version")
        if version != CARD_VERSION:
            raise ValueError(f"{where}: model card version {version!r}, this bsn-edge reads {CARD_VERSION}")

        def get(key: str, required: bool = True) -> Any:
            if key not in d or (required and d[key] is None and key != "threshold"):
                if required:
                    raise ValueError(f"{where}: model card key {key!r} is missing")
                return None
            return d[key]

        def build(key: str, fn):
            v = get(key, required=key not in OPTIONAL_FIELDS)
            try:
                return fn(v)
            except (TypeError, ValueError, KeyError) as e:
                raise ValueError(f"{where}: model card key {key!r} is bad ({v!r:.120}): {e}") from None

        intr = lambda v: None if v is None else Intrinsics.from_dict(v, "intrinsics")  # noqa: E731
        card_fields = {
            "variant": build("variant", str),
            "spec": build("spec", lambda v: dict(v)),
            "input_size": build("input_size", lambda v: _pair(v, int)),
            "threshold": build("threshold", lambda v: None if v is None else float(v)),
            "camera": build("camera", intr),
            "depth_range": build("depth_range", lambda v: _pair(v, float)),
            "quantization": build("quantization", str),
            "config_digest": build("config_digest", lambda v: "" if v is None else str(v)),
            "weights_sha256": build("weights_sha256", str),
            "train_camera": build("train_camera", intr),
            "graph_sha256": build("graph_sha256", lambda v: "" if v is None else str(v)),
            "self_test": build("self_test", _self_test),
            "mounting": build("mounting", lambda v: EARLY_MOUNTING if v is None else Mounting.from_dict(v, "mounting")),
            "training": build("training", lambda v: None if v is None else TrainingRecord.from_dict(v)),
        }
        try:
            return cls(**card_fields)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None

    # -- ONNX metadata_props -------------------------------------------------------------------

    def to_metadata(self) -> dict[str, str]:
        """``bsn.<field>`` -> JSON text, plus ``bsn.card_sha256`` over all the others."""
        props = {f"{PREFIX}{k}": json.dumps(v, sort_keys=True) for k, v in self.to_dict().items()}
        props[CARD_SHA_KEY] = card_digest(props)
        return props

    @classmethod
    def from_metadata(cls, props: Mapping[str, str], where: str = "model",
                      digests: tuple[DigestVersion, ...] = (DigestVersion.V2,)) -> ModelCard:
        """Read a card from ONNX metadata: ``bsn.card_sha256`` must match (in one of ``digests``: a
        model sealed before the canonical digest is read only to be resealed), and the entries must be
        exactly the card's fields (``training`` may be absent), each strict JSON."""
        ours = {k: v for k, v in props.items() if k.startswith(PREFIX)}
        if not ours:
            raise ValueError(f"{where}: not a bsn-export model (no {PREFIX}* metadata)")
        if f"{PREFIX}card_version" not in ours:
            return cls._from_legacy_metadata(ours, where)
        stored = ours.get(CARD_SHA_KEY)
        if stored is None:
            raise ValueError(f"{where}: model card key {CARD_SHA_KEY!r} is missing")
        matched = [v for v in digests if stored == card_digest(ours, v)]
        if not matched:
            if DigestVersion.V1 not in digests and stored == card_digest(ours, DigestVersion.V1):
                raise ValueError(f"{where}: sealed by an earlier bsn-edge, whose card digest was not canonical; "
                                 "export it again, or reseal it if you trust the file (bsn-export --reseal "
                                 "MODEL.onnx --out NEW.onnx --sign KEY.pem)")
            raise ValueError(f"{where}: the model card's metadata is damaged ({CARD_SHA_KEY} does not match)")
        fields_ = {k[len(PREFIX):]: v for k, v in ours.items() if k != CARD_SHA_KEY}
        unknown = sorted(set(fields_) - set(CARD_FIELDS))
        # a card sealed canonically carries every field; one sealed before may lack those added since
        optional = {"training"} if DigestVersion.V2 in matched else {"training", *OPTIONAL_FIELDS}
        missing = sorted(set(CARD_FIELDS) - set(fields_) - optional)
        if unknown or missing:
            what = [f"unknown {', '.join(repr(PREFIX + k) for k in unknown)}"] if unknown else []
            what += [f"missing {', '.join(repr(PREFIX + k) for k in missing)}"] if missing else []
            raise ValueError(f"{where}: the model card's entries are not a card's ({'; '.join(what)})")
        d: dict[str, Any] = {}
        for k, v in fields_.items():
            try:
                d[k] = _strict_json(v)
            except ValueError as e:
                raise ValueError(f"{where}: metadata {PREFIX + k!r} is not a card's JSON ({e}): {v!r:.80}") from None
        return cls.from_dict(d, where)

    @classmethod
    def _from_legacy_metadata(cls, props: Mapping[str, str], where: str) -> ModelCard:
        """Models exported before cards existed (``bsn.intrinsics`` and friends, no seal)."""
        def value(text: str) -> Any:
            try:
                return json.loads(text)
            except json.JSONDecodeError:
                return text  # strings were stored as they are

        return cls.from_legacy({k[len(PREFIX):]: value(v) for k, v in props.items()}, where)

    @classmethod
    def from_legacy(cls, d: Mapping[str, Any], where: str) -> ModelCard:
        """A card from the flat records written before cards (checkpoint.json or ONNX metadata).
        Their depth head was the one of this version: 0.5-120 m."""
        if not d.get("intrinsics"):
            raise ValueError(f"{where}: no intrinsics recorded; the model's camera is unknown")
        size = d.get("input_size") or [d["intrinsics"]["height"], d["intrinsics"]["width"]]
        cam = Intrinsics(**d["intrinsics"])
        if (cam.height, cam.width) != tuple(size):
            cam = cam.scaled(int(size[1]), int(size[0]))
        return cls.from_dict({
            "card_version": CARD_VERSION, "variant": d.get("variant") or d.get("model"), "spec": d.get("spec", {}),
            "input_size": size, "threshold": d.get("threshold"), "camera": cam.to_dict(),
            "depth_range": [0.5, 120.0], "quantization": d.get("quantization") or FP32,
            "config_digest": d.get("config_digest", ""), "weights_sha256": d.get("weights_sha256"),
            "train_camera": None, "graph_sha256": "", "self_test": None,
        }, f"{where} (written before model cards)")


def card_digest(props: Mapping[str, str], version: DigestVersion = DigestVersion.V2) -> str:
    """sha256 over the sorted ``bsn.*`` entries other than the digest itself: each key and each value
    as UTF-8 with its length in 8 bytes before it (V2), so the byte stream names one card only."""
    h = hashlib.sha256()
    if version == DigestVersion.V2:
        h.update(_DIGEST_DOMAIN)
    for k in sorted(props):
        if k.startswith(PREFIX) and k != CARD_SHA_KEY:
            key, value = k.encode(), props[k].encode()
            if version == DigestVersion.V2:
                h.update(len(key).to_bytes(8, "big") + key + len(value).to_bytes(8, "big") + value)
            else:
                h.update(key + b"\0" + value + b"\0")
    return h.hexdigest()


def _strict_json(text: str) -> Any:
    """JSON as a card writes it: no NaN or infinity, no control characters inside strings."""
    def refuse(name: str) -> Any:
        raise ValueError(f"{name} is not a number a card holds")

    return json.loads(text, parse_constant=refuse)


def _pair(v: Any, kind: type) -> tuple:
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise ValueError("expected two numbers")
    a, b = kind(v[0]), kind(v[1])
    if kind is int and (a != v[0] or b != v[1]):
        raise ValueError("expected two integers")
    return a, b


def _self_test(v: Any) -> SelfTest | None:
    if v is None:
        return None
    return SelfTest(grid=_pair(v["grid"], int), prob=tuple(float(x) for x in v["prob"]),
                    depth=tuple(float(x) for x in v["depth"]), prob_atol=float(v["prob_atol"]),
                    depth_rtol=float(v["depth_rtol"]))
