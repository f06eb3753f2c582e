"""Whose model is this: Ed25519 signatures over a model's seal, checked against keys the user trusts.

The seal (``bsn.card_sha256`` over the card, the card's ``graph_sha256`` over the graph and weights)
proves a model intact, not authentic: anyone can edit a threshold and re-digest the card. A signature
over both digests, made with a private key its owner keeps, proves who sealed it. It is stored in
the model's metadata under :data:`SIGNATURE_KEY` (outside the card's ``bsn.*`` entries, so signing
does not change the seal) as ``{"key": KEY_ID, "signature": BASE64}``.

``bsn-run`` checks every model as signed firmware is checked (:class:`TrustPolicy`): against the
project's key (shipped in ``keys/``), the keys in the user's trust folder (:func:`user_trust_dir`)
and any given with ``--trust``. A model unsigned or signed by another key runs only when asked in
words (``--allow-unsigned``), and then the status says so on every cycle; a signature that does not
match its model is refused always.

Keys are PEM files (``bsn-export --new-key`` writes a pair); a key source is one public key file, a
file of several, or a folder of them. ``cryptography`` is imported only when a key is read.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bsn_edge.user_file import read_user_file

SIGNATURE_KEY = "bsnsig.ed25519"
_MESSAGE = b"bsn-edge model seal v1\0"
_PEM = re.compile(rb"-----BEGIN PUBLIC KEY-----.+?-----END PUBLIC KEY-----", re.S)


PROJECT_KEYS = Path(__file__).with_name("keys")    # the project's public keys: the shipped models are signed
TRUST_ENV = "BSN_EDGE_TRUST"                       # a folder of trusted keys instead of the user's default one


class UntrustedModelError(ValueError):
    """The model is not signed by a trusted key (the message says which way)."""


class NotSignedError(UntrustedModelError):
    """The model carries no signature, or one by a key not trusted here (``--allow-unsigned`` runs it)."""


def user_trust_dir() -> Path:
    """The folder whose public keys ``bsn-run`` trusts besides the project's: ``$BSN_EDGE_TRUST``, else
    ``$XDG_CONFIG_HOME/bsn-edge/trust``, else ``~/.config/bsn-edge/trust``."""
    if os.environ.get(TRUST_ENV):
        return Path(os.environ[TRUST_ENV])
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    return base / "bsn-edge" / "trust"


@dataclass(frozen=True)
class Verdict:
    """What the check found: the trusted key that signed the model ("" when none did), and why not."""

    signer: str
    note: str = ""

    @property
    def authentic(self) -> bool:
        return bool(self.signer)


@dataclass(frozen=True)
class TrustPolicy:
    """Which keys sign models that may run, and whether others may run anyway (``allow_unsigned``)."""

    keys: Mapping[str, Any] = field(default_factory=dict)
    allow_unsigned: bool = False
    sources: tuple[str, ...] = ()     # where the keys came from, for messages

    @classmethod
    def default(cls, extra: Iterable[str | Path] = (), allow_unsigned: bool = False) -> TrustPolicy:
        """The project's keys, the user's trust folder (when it exists) and ``extra`` key files or folders."""
        keys: dict[str, Any] = {}
        sources = []
        for where, required in ((PROJECT_KEYS, True), (user_trust_dir(), False), *((Path(e), True) for e in extra)):
            if not required and not where.is_dir():
                continue
            found = load_public_keys(where, allow_empty=not required)
            keys.update(found)
            sources.append(str(where))
        return cls(keys, allow_unsigned, tuple(sources))

    def check(self, metadata: Mapping[str, str], graph_sha256: str, card_sha256: str,
              where: str = "model") -> Verdict:
        """The verdict on a model; ``UntrustedModelError`` when it may not run."""
        try:
            return Verdict(verify(metadata, graph_sha256, card_sha256, self.keys, where))
        except NotSignedError as e:
            if not self.allow_unsigned:
                raise NotSignedError(f"{e}. bsn-run runs models signed by the project's key, by a key in "
                                     f"{user_trust_dir()} or by one given with --trust KEY.pub; sign yours with "
                                     "bsn-export --sign KEY.pem, or run it anyway with --allow-unsigned (the status "
                                     "then says Model_Unsigned on every cycle)") from None
            return Verdict("", str(e))


def signed_message(graph_sha256: str, card_sha256: str) -> bytes:
    """What a signature covers: the graph's digest and the card's."""
    return _MESSAGE + graph_sha256.encode() + b"\0" + card_sha256.encode()


def key_id(public_key: Any) -> str:
    """A short name of an Ed25519 public key: the first 16 hex digits of the sha256 of its raw bytes."""
    from cryptography.hazmat.primitives import serialization

    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def load_public_keys(path: str | Path, allow_empty: bool = False) -> dict[str, Any]:
    """The Ed25519 public keys in a PEM file (one or several) or in the ``.pub`` / ``.pem`` files of a
    folder, by :func:`key_id`. ``ValueError`` names a file that holds no usable key (and a folder with
    none, unless ``allow_empty``)."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import load_pem_public_key

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"--trust {p}: no such key file or folder")
    files = sorted(q for q in p.iterdir() if q.suffix in (".pub", ".pem")) if p.is_dir() else [p]
    keys: dict[str, Any] = {}
    for f in files:
        if p.is_dir() and not f.is_file():
            continue                      # a FIFO or device named like a key in a trust folder is no key
        blocks = _PEM.findall(read_user_file(f, "key"))
        if not blocks and not p.is_dir():
            raise ValueError(f"{f}: no PEM public key in it (bsn-export --new-key writes KEY.pub)")
        for block in blocks:
            try:
                key = load_pem_public_key(block)
            except ValueError as e:
                raise ValueError(f"{f}: not a public key ({e})") from None
            if not isinstance(key, Ed25519PublicKey):
                raise ValueError(f"{f}: a {type(key).__name__}, not an Ed25519 key")
            keys[key_id(key)] = key
    if not keys and not allow_empty:
        raise ValueError(f"--trust {p}: no Ed25519 public key found")
    return keys


def read_signature(metadata: Mapping[str, str]) -> dict[str, str] | None:
    """The signature record of a model's metadata, or None when it is unsigned."""
    text = metadata.get(SIGNATURE_KEY)
    if text is None:
        return None
    try:
        rec = json.loads(text)
    except json.JSONDecodeError:
        rec = None
    if not isinstance(rec, dict) or not isinstance(rec.get("key"), str) or not isinstance(rec.get("signature"), str):
        raise UntrustedModelError(f"the model's signature entry ({SIGNATURE_KEY}) is damaged")
    return rec


def verify(metadata: Mapping[str, str], graph_sha256: str, card_sha256: str, keys: Mapping[str, Any],
           where: str = "model") -> str:
    """The id of the trusted key that signed this seal; ``UntrustedModelError`` otherwise."""
    from cryptography.exceptions import InvalidSignature

    rec = read_signature(metadata)
    if rec is None:
        raise NotSignedError(f"{where}: the model is not signed")
    key = keys.get(rec["key"])
    if key is None:
        raise NotSignedError(f"{where}: signed by key {rec['key']}, which is not among the trusted keys "
                             f"({', '.join(sorted(keys)) or 'none'})")
    try:
        key.verify(base64.b64decode(rec["signature"], validate=True), signed_message(graph_sha256, card_sha256))
    except (InvalidSignature, ValueError):
        raise UntrustedModelError(f"{where}: the signature of key {rec['key']} does not match this model: it was "
                                  "changed after it was signed") from None
    return rec["key"]
