"""The shipped default as the package carries it: package data beside its card, sealed, signed with the project's
release key (key id ``cbd0e9778152c6cb``, the keys' README: the first 16 hex digits of the sha256 of the raw
public key), and the card beside it the model's own."""

import hashlib
import json
import tomllib
from pathlib import Path

import bsn_edge
from bsn_edge.default_model import DEFAULT_CARD, DEFAULT_MODEL

ROOT = Path(__file__).resolve().parents[2]
RELEASE_KEY_ID = "cbd0e9778152c6cb"


def test_the_default_model_lives_in_the_package_and_is_package_data():
    pkg = Path(bsn_edge.__file__).resolve().parent / "default_model"
    assert DEFAULT_MODEL.parent == pkg and DEFAULT_MODEL.is_file() and not DEFAULT_MODEL.is_symlink()
    assert DEFAULT_CARD.is_file() and DEFAULT_CARD.parent == pkg
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "bsn_edge.default_model" in tool["packages"]
    assert {"*.onnx", "*.json"} <= set(tool["package-data"]["bsn_edge.default_model"])


def test_the_default_is_signed_with_the_release_key_and_its_card_is_the_one_beside_it():
    from cryptography.hazmat.primitives import serialization

    from bsn_edge.modelfile.trust import PROJECT_KEYS, load_public_keys
    from bsn_edge.runtime import Engine

    pub = serialization.load_pem_public_key((PROJECT_KEYS / "bsn-edge-project.pub").read_bytes())
    raw = pub.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    assert hashlib.sha256(raw).hexdigest()[:16] == RELEASE_KEY_ID, "the package's key is the release key"
    engine = Engine(DEFAULT_MODEL, trust=load_public_keys(PROJECT_KEYS))      # the project's keys only
    assert engine.authentic and engine.verdict.signer == RELEASE_KEY_ID
    beside = json.loads(DEFAULT_CARD.read_text())["card"]
    assert beside["threshold"] == engine.threshold == 0.25
    assert beside["graph_sha256"] == engine.card.graph_sha256 and beside["weights_sha256"] == engine.card.weights_sha256
