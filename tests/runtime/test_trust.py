"""Models that are not ours: with --trust, only a model signed by a trusted key runs. An intact seal is
not enough: anyone can edit a card and re-digest it."""

import json
import shutil

import can
import onnx
import pytest

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import decode
from bsn_edge.card import CARD_SHA_KEY, card_digest
from bsn_edge.cli import export as export_cli
from bsn_edge.cli import run as run_cli
from bsn_edge.modelfile.trust import SIGNATURE_KEY, load_public_keys
from bsn_edge.runtime import Engine
from bsn_edge.runtime.engine import ModelError


@pytest.fixture
def keys(tmp_path):
    for name in ("ours", "theirs"):
        assert export_cli.main(["--new-key", str(tmp_path / f"{name}.pem")]) == 0
    return tmp_path / "ours.pem", tmp_path / "theirs.pem"


def signed_copy(model, tmp_path, key, name="signed.onnx"):
    out = tmp_path / name
    assert export_cli.main(["--reseal", str(model), "--out", str(out), "--sign", str(key)]) == 0
    return out


def test_a_signed_model_runs_for_its_key_only(setup, tmp_path, keys):
    model, _ = setup
    ours, theirs = keys
    signed = signed_copy(model, tmp_path, ours)
    engine = Engine(signed, trust=load_public_keys(f"{ours}.pub"))
    assert len(engine.signer) == 16
    with pytest.raises(ModelError, match="not among the trusted keys"):
        Engine(signed, trust=load_public_keys(f"{theirs}.pub"))
    with pytest.raises(ModelError, match="not signed"):
        Engine(model, trust=load_public_keys(f"{ours}.pub"))
    folder = tmp_path / "trusted"
    folder.mkdir()
    for k in keys:
        shutil.copy(f"{k}.pub", folder)
    assert Engine(signed, trust=load_public_keys(folder)).signer == engine.signer
    assert Engine(model).signer == "", "without --trust any intact model runs, as before"


def test_a_resealed_edit_keeps_its_seal_but_loses_its_signature(setup, tmp_path, keys):
    """The threshold edited and bsn.card_sha256 recomputed: intact, so it runs without --trust; its
    signature no longer matches, so it is refused with it."""
    model, _ = setup
    ours, _ = keys
    signed = signed_copy(model, tmp_path, ours)
    m = onnx.load(str(signed))
    props = {p.key: p.value for p in m.metadata_props}
    props["bsn.threshold"] = json.dumps(0.05)
    props[CARD_SHA_KEY] = card_digest({k: v for k, v in props.items() if k.startswith("bsn.")})
    del m.metadata_props[:]
    for k, v in props.items():
        e = m.metadata_props.add()
        e.key, e.value = k, v
    edited = tmp_path / "edited.onnx"
    onnx.save(m, str(edited))
    assert Engine(edited).card.threshold == 0.05
    with pytest.raises(ModelError, match="does not match this model"):
        Engine(edited, trust=load_public_keys(f"{ours}.pub"))
    assert SIGNATURE_KEY in props


def test_bsn_run_refuses_an_unsigned_model_with_unavailable_and_a_message(setup, tmp_path, keys, capsys):
    model, clip = setup
    ours, _ = keys
    with can.Bus(interface="virtual", channel="bsn-trust") as rx:
        code = run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--trust", f"{ours}.pub",
                             "--can", "virtual:bsn-trust"])
        states = []
        while (msg := rx.recv(timeout=0.2)) is not None:
            d = decode(msg.arbitration_id, msg.data)
            if d is not None and d.name == "BSN_Status":
                states.append(d.signals["System_State"])
    err = capsys.readouterr().err
    assert code == 2 and "not signed" in err and "Traceback" not in err
    assert states == [SystemState.UNAVAILABLE]


def test_keys_are_never_overwritten_and_bad_keys_are_named(tmp_path, keys, capsys):
    ours, _ = keys
    assert ours.stat().st_mode & 0o777 == 0o600, "the private key is readable by its owner only"
    before = ours.read_bytes()
    assert export_cli.main(["--new-key", str(ours)]) == 2
    assert ours.read_bytes() == before and "not overwritten" in capsys.readouterr().err
    junk = tmp_path / "junk.pub"
    junk.write_text("not a key")
    with pytest.raises(ValueError, match=r"junk\.pub: no PEM public key"):
        load_public_keys(junk)


def test_the_shipped_default_is_signed_with_the_projects_key():
    from bsn_edge.cli.demo import DEFAULT_MODEL, PROJECT_KEY
    if not DEFAULT_MODEL.is_file():
        pytest.skip("the shipped model is not in this checkout")
    engine = Engine(DEFAULT_MODEL, trust=load_public_keys(PROJECT_KEY))
    assert engine.signer == next(iter(load_public_keys(PROJECT_KEY)))


def test_reseal_turns_a_model_from_before_seals_into_one_the_runtime_runs(setup, tmp_path):
    """A model exported before models were sealed (no graph digest, no self-test answer) is refused;
    bsn-export --reseal records both, and the resealed file runs with the same card."""
    from bsn_edge.export.seal import read_card, set_metadata
    model, _ = setup
    card = read_card(model)
    m = onnx.load(str(model))
    set_metadata(m, card.replace(graph_sha256="", self_test=None))
    old = tmp_path / "old.onnx"
    onnx.save(m, str(old))
    with pytest.raises(ModelError, match="no integrity digest"):
        Engine(old)
    assert export_cli.main(["--reseal", str(old), "--out", str(tmp_path / "new.onnx")]) == 0
    engine = Engine(tmp_path / "new.onnx")
    assert engine.card.graph_sha256 == card.graph_sha256 and engine.card.threshold == card.threshold
    assert engine.self_test["max_abs_prob"] < 1e-5, "its own answer, recorded at reseal"


def test_a_file_swapped_after_the_check_is_not_what_runs(setup, tmp_path, keys, monkeypatch):
    """The model is read once: the bytes that were hashed and whose signature was checked are the bytes
    onnxruntime runs. Here the file is replaced by another between the check and the session; the
    engine still runs the verified model, frame for frame."""
    import numpy as np

    import bsn_edge.runtime.engine as engine_mod
    from bsn_edge.modelfile.read import session as real_session
    model, _ = setup
    ours, _ = keys
    signed = signed_copy(model, tmp_path, ours)
    original = signed.read_bytes()
    other = tmp_path / "other.onnx"
    assert export_cli.main(["--reseal", str(model), "--out", str(other)]) == 0   # valid, unsigned, same graph

    def swap_then_open(src, *args, **kwargs):
        signed.write_bytes(b"\x08\x07" + other.read_bytes()[2:-7])      # anything but the verified file
        return real_session(src, *args, **kwargs)
    monkeypatch.setattr(engine_mod, "session", swap_then_open)
    engine = Engine(signed, trust=load_public_keys(f"{ours}.pub"))
    assert signed.read_bytes() != original
    frame = np.random.default_rng(0).integers(0, 256, (1, *engine.card.input_size, 3), np.uint8)
    want = real_session(original, 2, False, exact_x64=not engine.card.seven_bit_weights).run(None, {"frame": frame})
    got = engine.infer(frame)
    assert all(np.allclose(a, b, atol=1e-6) for a, b in zip(want, got, strict=True))
