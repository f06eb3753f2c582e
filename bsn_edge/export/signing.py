"""Signing exported models with an Ed25519 key (the check is :mod:`bsn_edge.modelfile.trust`).

``new_key`` writes a key pair: the private key (PEM, readable by its owner only) and, beside it,
``.pub`` to hand to every ``bsn-run --trust``. ``sign`` adds the signature over a sealed model's
digests to its metadata; the graph and the seal are unchanged.
"""

from __future__ import annotations

import base64
import json
import os
from pathlib import Path

import onnx
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from bsn_edge.card import CARD_SHA_KEY
from bsn_edge.modelfile.read import graph_digest
from bsn_edge.modelfile.trust import SIGNATURE_KEY, key_id, signed_message
from bsn_edge.sequence.images import atomic_write_bytes


def new_key(path: str | Path, force: bool = False) -> tuple[Path, Path, str]:
    """Write a new private key to ``path`` (mode 0600) and its public key to ``path`` + ``.pub``;
    returns both paths and the key id. An existing key is never overwritten without ``force``."""
    priv = Path(path)
    pub = priv.with_name(priv.name + ".pub")
    for f in (priv, pub):
        if f.exists() and not force:
            raise FileExistsError(f"{f} exists; a key is not overwritten without --force (models signed with it "
                                  "could no longer be re-signed)")
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    priv.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(priv, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as key_file:
        key_file.write(pem)
    public = key.public_key()
    atomic_write_bytes(pub, public.public_bytes(serialization.Encoding.PEM,
                                                serialization.PublicFormat.SubjectPublicKeyInfo))
    return priv, pub, key_id(public)


def load_private_key(path: str | Path) -> Ed25519PrivateKey:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"--sign {p}: no such key file (bsn-export --new-key {p} makes one)")
    try:
        key = serialization.load_pem_private_key(p.read_bytes(), password=None)
    except (ValueError, TypeError) as e:
        raise ValueError(f"--sign {p}: not an unencrypted PEM private key ({e})") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise ValueError(f"--sign {p}: a {type(key).__name__}, not an Ed25519 key")
    return key


def sign(model_path: str | Path, key_path: str | Path, out: str | Path | None = None) -> str:
    """Sign the sealed model at ``model_path`` (written to ``out``, default in place); returns the key id."""
    key = load_private_key(key_path)
    model = onnx.load(str(model_path))
    props = {p.key: p.value for p in model.metadata_props}
    if CARD_SHA_KEY not in props:
        raise ValueError(f"{model_path}: not sealed (bsn-export --reseal seals it first)")
    kid = key_id(key.public_key())
    data = model.SerializeToString()
    sig = key.sign(signed_message(graph_digest(data), props[CARD_SHA_KEY]))
    kept = [(p.key, p.value) for p in model.metadata_props if p.key != SIGNATURE_KEY]
    del model.metadata_props[:]
    for k, v in [*kept, (SIGNATURE_KEY, json.dumps({"key": kid, "signature": base64.b64encode(sig).decode()}))]:
        e = model.metadata_props.add()
        e.key, e.value = k, v
    atomic_write_bytes(Path(out) if out is not None else Path(model_path), model.SerializeToString())
    return kid
