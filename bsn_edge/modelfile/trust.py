"""Whose model is this: Ed25519 signatures over a model's seal, checked against keys the user trusts.

The seal (``bsn.card_sha256`` over the card, the card's ``graph_sha256`` over the graph and weights)
proves a model intact, not authentic: anyone can edit a threshold and re-digest the card. A signature
over both digests, made with a private key its owner keeps, proves who sealed it. It is stored in
the model's metadata under :data:`SIGNATURE_KEY` (outside the card's ``bsn.*`` entries, so signing
does not change the seal) as ``{"key": KEY_ID, "signature": BASE64}``. ``bsn-run --trust KEYS``
refuses a model that is unsigned, signed by a key not in KEYS, or whose signature does not match.

Keys are PEM files (``bsn-export --new-key`` writes a pair); ``KEYS`` is one public key file, a file
of several, or a folder of them. ``cryptography`` is imported only when a key is read.
"""

from __future__ import annotations

import base64
import hashlib
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

SIGNATURE_KEY = "bsnsig.ed25519"
_MESSAGE = b"bsn-edge model seal v1\0"
_PEM = re.compile(rb"-----BEGIN PUBLIC KEY-----.+?-----END PUBLIC KEY-----", re.S)


class UntrustedModelError(ValueError):
    """The model is not signed by a trusted key (the message says which way)."""


def signed_message(graph_sha256: str, card_sha256: str) -> bytes:
    """What a signature covers: the graph's digest and the card's."""
    return _MESSAGE + graph_sha256.encode() + b"\0" + card_sha256.encode()


def key_id(public_key: Any) -> str:
    """A short name of an Ed25519 public key: the first 16 hex digits of the sha256 of its raw bytes."""
    from cryptography.hazmat.primitives import serialization

    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def load_public_keys(path: str | Path) -> dict[str, Any]:
    """The Ed25519 public keys in a PEM file (one or several) or in the ``.pub`` / ``.pem`` files of a
    folder, by :func:`key_id`. ``ValueError`` names a file that holds no usable key."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import load_pem_public_key

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"--trust {p}: no such key file or folder")
    files = sorted(q for q in p.iterdir() if q.suffix in (".pub", ".pem")) if p.is_dir() else [p]
    keys: dict[str, Any] = {}
    for f in files:
        blocks = _PEM.findall(f.read_bytes())
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
    if not keys:
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
        raise UntrustedModelError(f"{where}: the model is not signed, and --trust asks for a signed one "
                                  "(bsn-export --sign KEY.pem signs a model)")
    key = keys.get(rec["key"])
    if key is None:
        raise UntrustedModelError(f"{where}: signed by key {rec['key']}, which is not among the trusted keys "
                                  f"({', '.join(sorted(keys))})")
    try:
        key.verify(base64.b64decode(rec["signature"], validate=True), signed_message(graph_sha256, card_sha256))
    except (InvalidSignature, ValueError):
        raise UntrustedModelError(f"{where}: the signature of key {rec['key']} does not match this model: it was "
                                  "changed after it was signed") from None
    return rec["key"]
