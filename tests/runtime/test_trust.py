"""Models that are not ours: bsn-run runs only a model signed by a trusted key (the project's, the trust
folder's, --trust), unless told in words (--allow-unsigned), and then the status says so on every cycle.
An intact seal is not enough: anyone can edit a card and re-digest it."""

import json
import shutil

import can
import onnx
import pytest

from bsn_edge.alerts import SystemState
from bsn_edge.card import CARD_SHA_KEY, card_digest
from bsn_edge.cli import export as export_cli
from bsn_edge.cli import run as run_cli
from bsn_edge.modelfile.trust import SIGNATURE_KEY, TrustPolicy, load_public_keys
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


def with_metadata(model, tmp_path, name, props):
    """A copy of ``model`` whose metadata is ``props`` (the graph's bytes untouched)."""
    m = onnx.load(str(model))
    del m.metadata_props[:]
    for k, v in props.items():
        e = m.metadata_props.add()
        e.key, e.value = k, v
    out = tmp_path / name
    onnx.save(m, str(out))
    return out


def unsigned_copy(model, tmp_path, name="unsigned.onnx"):
    """The model with its signature taken out: still sealed (the signature lies outside the seal)."""
    props = {p.key: p.value for p in onnx.load(str(model)).metadata_props if p.key != SIGNATURE_KEY}
    return with_metadata(model, tmp_path, name, props)


def rethresholded(model, tmp_path, threshold):
    """The model with its threshold edited and its card re-digested: intact, but not as it was signed."""
    props = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    props["bsn.threshold"] = json.dumps(threshold)
    props[CARD_SHA_KEY] = card_digest({k: v for k, v in props.items() if k.startswith("bsn.")})
    return with_metadata(model, tmp_path, "edited.onnx", props)


def bus_run(channel, argv):
    """bsn-run on a virtual bus: (exit code, the status frames' signals decoded by cantools)."""
    import cantools

    from bsn_edge.alerts.can_codec import DBC_PATH
    db = cantools.database.load_file(str(DBC_PATH))
    with can.Bus(interface="virtual", channel=channel) as rx:
        code = run_cli.main([*argv, "--can", f"virtual:{channel}"])
        st = [db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False)
              for m in iter(lambda: rx.recv(0.2), None) if m.arbitration_id == 0x501]
    return code, st


def test_a_signed_model_runs_for_its_key_only(setup, tmp_path, keys):
    model, _ = setup
    ours, theirs = keys
    signed = signed_copy(model, tmp_path, ours)
    engine = Engine(signed, trust=load_public_keys(f"{ours}.pub"))
    assert len(engine.signer) == 16
    with pytest.raises(ModelError, match="not among the trusted keys"):
        Engine(signed, trust=load_public_keys(f"{theirs}.pub"))
    with pytest.raises(ModelError, match="not signed"):
        Engine(unsigned_copy(model, tmp_path), trust=load_public_keys(f"{ours}.pub"))
    folder = tmp_path / "trusted"
    folder.mkdir()
    for k in keys:
        shutil.copy(f"{k}.pub", folder)
    assert Engine(signed, trust=load_public_keys(folder)).signer == engine.signer
    unchecked = Engine(model)
    assert unchecked.signer == "" and not unchecked.authentic, "a library user who checks nothing gets no verdict"


def test_a_resealed_edit_keeps_its_seal_but_loses_its_signature(setup, tmp_path, keys):
    """The threshold edited and bsn.card_sha256 recomputed: intact, so it runs without --trust; its
    signature no longer matches, so it is refused with it."""
    model, _ = setup
    ours, _ = keys
    signed = signed_copy(model, tmp_path, ours)
    edited = rethresholded(signed, tmp_path, 0.05)
    assert Engine(edited).card.threshold == 0.05
    with pytest.raises(ModelError, match="does not match this model"):
        Engine(edited, trust=load_public_keys(f"{ours}.pub"))
    assert SIGNATURE_KEY in {p.key for p in onnx.load(str(edited)).metadata_props}, "it kept its signature"


def test_bsn_run_refuses_an_unsigned_model_by_default_with_unavailable_and_a_message(setup, tmp_path, capsys):
    model, clip = setup
    bare = unsigned_copy(model, tmp_path)
    code, st = bus_run("bsn-trust", ["--model", str(bare), "--source", str(clip / "video.mp4")])
    err = capsys.readouterr().err
    assert code == 2 and "not signed" in err and "--allow-unsigned" in err and "Traceback" not in err
    assert [s["System_State"] for s in st] == [SystemState.UNAVAILABLE]


def test_a_model_signed_by_a_key_not_trusted_here_is_refused_until_its_key_is_given(setup, tmp_path, keys, capsys):
    model, clip = setup
    _, theirs = keys
    foreign = signed_copy(model, tmp_path, theirs)
    argv = ["--model", str(foreign), "--source", str(clip / "video.mp4"), "--calib", str(clip / "calibration.json")]
    code, _ = bus_run("bsn-foreign", argv)
    assert code == 2 and "not among the trusted keys" in capsys.readouterr().err
    code, st = bus_run("bsn-foreign", [*argv, "--trust", f"{theirs}.pub"])
    assert code == 0 and st and all(s["Model_Unsigned"] == 0 for s in st)


def test_allow_unsigned_runs_it_and_the_status_says_so_on_every_cycle(setup, tmp_path, capsys):
    model, clip = setup
    bare = unsigned_copy(model, tmp_path)
    summ = tmp_path / "s.json"
    code, st = bus_run("bsn-unsigned", ["--model", str(bare), "--source", str(clip / "video.mp4"), "--calib",
                                        str(clip / "calibration.json"), "--allow-unsigned", "--summary", str(summ)])
    assert code == 0 and len(st) > 5 and all(s["Model_Unsigned"] == 1 for s in st)
    assert st[-1]["System_State"] == SystemState.UNAVAILABLE
    s = json.loads(summ.read_text())["model"]
    assert s["authentic"] is False and s["signer"] == "" and "not signed" in s["trust_note"]
    out = capsys.readouterr()
    assert "model: UNSIGNED" in out.out and "warning" in out.err
    # the signed original on the same run: the flag stays clear
    code, st = bus_run("bsn-unsigned", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                        str(clip / "calibration.json")])
    assert code == 0 and all(s["Model_Unsigned"] == 0 for s in st)


def test_a_signature_that_does_not_match_is_refused_even_with_allow_unsigned(setup, tmp_path, keys, capsys):
    model, clip = setup
    ours, _ = keys
    edited = rethresholded(signed_copy(model, tmp_path, ours), tmp_path, 0.9)    # pushed up: it would report less
    code, st = bus_run("bsn-tampered", ["--model", str(edited), "--source", str(clip / "video.mp4"), "--trust",
                                        f"{ours}.pub", "--allow-unsigned"])
    assert code == 2 and "does not match" in capsys.readouterr().err
    assert [s["System_State"] for s in st] == [SystemState.UNAVAILABLE]


def test_reseal_needs_a_key_and_a_model_answering_nan_is_refused_with_a_message(setup, tmp_path, keys, capsys):
    import numpy as np
    from onnx import numpy_helper
    model, _ = setup
    ours, _ = keys
    assert export_cli.main(["--reseal", str(model), "--out", str(tmp_path / "r.onnx")]) == 2
    assert "--reseal needs --sign" in capsys.readouterr().err and not (tmp_path / "r.onnx").exists()
    m = onnx.load(str(model))
    w = next(t for t in m.graph.initializer if numpy_helper.to_array(t).dtype == np.float32
             and numpy_helper.to_array(t).size > 100)
    w.CopyFrom(numpy_helper.from_array(np.full_like(numpy_helper.to_array(w), np.nan), w.name))
    nan = tmp_path / "nan.onnx"
    onnx.save(m, str(nan))
    assert export_cli.main(["--reseal", str(nan), "--out", str(tmp_path / "n.onnx"), "--sign", str(ours)]) == 2
    err = capsys.readouterr().err
    assert "non-finite" in err and "Traceback" not in err and not (tmp_path / "n.onnx").exists()


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


def test_the_shipped_default_is_signed_with_the_projects_key_and_runs_by_default():
    from bsn_edge.default_model import DEFAULT_MODEL
    from bsn_edge.modelfile.trust import PROJECT_KEYS
    if not DEFAULT_MODEL.is_file():
        pytest.skip("the shipped model is not in this checkout")
    engine = Engine(DEFAULT_MODEL, trust=TrustPolicy.default())
    assert engine.authentic and engine.signer in load_public_keys(PROJECT_KEYS)


def test_reseal_turns_a_model_from_before_seals_into_one_the_runtime_runs(setup, tmp_path, keys):
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
    assert export_cli.main(["--reseal", str(old), "--out", str(tmp_path / "new.onnx"), "--sign", str(keys[0])]) == 0
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
    assert export_cli.main(["--reseal", str(model), "--out", str(other), "--sign", str(keys[1])]) == 0  # same graph

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


def _nul_joined(props) -> bytes:
    """The byte stream the first card digest hashed: sorted ``bsn.*`` keys and values joined by NUL."""
    return b"".join(k.encode() + b"\0" + props[k].encode() + b"\0" for k in sorted(props)
                    if k.startswith("bsn.") and k != CARD_SHA_KEY)


@pytest.mark.parametrize("into", ["key", "value"])
def test_a_card_whose_entries_are_merged_or_re_split_is_refused_though_its_bytes_are_the_same(
        setup, tmp_path, keys, into):
    """``bsn.model`` and ``bsn.mounting`` made one entry, the mounting carried inside the merged key (or
    the merged value): NUL-joined, the same bytes as the signed card, so a digest over them would still
    match and the signature verify, while the card read would fall back to the default mounting."""
    model, _ = setup
    ours, _ = keys
    signed = signed_copy(model, tmp_path, ours)
    props = {p.key: p.value for p in onnx.load(str(signed)).metadata_props}
    merged = {k: v for k, v in props.items() if k not in ("bsn.model", "bsn.mounting")}
    if into == "key":
        merged["bsn.model\0" + props["bsn.model"] + "\0bsn.mounting"] = props["bsn.mounting"]
    else:
        merged["bsn.model"] = props["bsn.model"] + "\0bsn.mounting\0" + props["bsn.mounting"]
    assert _nul_joined(merged) == _nul_joined(props)
    bad = with_metadata(model, tmp_path, "merged.onnx", merged)
    with pytest.raises(ModelError, match=r"damaged|not a card"):
        Engine(bad, trust=load_public_keys(f"{ours}.pub"))
    code, st = bus_run(f"bsn-merged-{into}", ["--model", str(bad), "--source", str(setup[1] / "rgb"),
                                              "--trust", f"{ours}.pub"])
    assert code == 2 and [s["System_State"] for s in st] == [SystemState.UNAVAILABLE]


def test_a_card_with_an_entry_of_its_own_is_refused_even_re_digested(setup, tmp_path):
    """Entries beyond the card's fields (or one of them missing) are not a card, whatever the digest says."""
    model, _ = setup
    props = {p.key: p.value for p in onnx.load(str(model)).metadata_props if p.key != SIGNATURE_KEY}
    extra = {**props, "bsn.mounting_override": json.dumps({"height_m": 2.5})}
    extra[CARD_SHA_KEY] = card_digest(extra)
    with pytest.raises(ModelError, match=r"unknown 'bsn\.mounting_override'"):
        Engine(with_metadata(model, tmp_path, "extra.onnx", extra))
    fewer = {k: v for k, v in props.items() if k != "bsn.mounting"}
    fewer[CARD_SHA_KEY] = card_digest(fewer)
    with pytest.raises(ModelError, match=r"missing 'bsn\.mounting'"):
        Engine(with_metadata(model, tmp_path, "fewer.onnx", fewer))


def test_the_card_digest_is_its_length_prefixed_entries():
    """The digest by hand: sha256 over the domain tag, then each sorted ``bsn.*`` key and value with its
    length in 8 big-endian bytes before it, the digest's own entry left out and other keys ignored."""
    import hashlib
    props = {"bsn.b": "[1]", "bsn.a": '"x"', CARD_SHA_KEY: "ignored", "other": "ignored"}
    want = hashlib.sha256(b"bsn-edge model card v2\0"
                          + (5).to_bytes(8, "big") + b"bsn.a" + (3).to_bytes(8, "big") + b'"x"'
                          + (5).to_bytes(8, "big") + b"bsn.b" + (3).to_bytes(8, "big") + b"[1]").hexdigest()
    assert card_digest(props) == want


def test_reseal_with_a_new_threshold_keeps_the_graph_to_the_bit_and_says_where_it_was_chosen(setup, tmp_path, keys,
                                                                                                capsys):
    """``--threshold P --threshold-from TEXT`` re-decides a sealed model: its card decides at P and its
    training record names where P was chosen; the graph, and so the self-test answer, stay as they are."""
    from bsn_edge.card import TrainingRecord
    from bsn_edge.export.seal import read_card, set_metadata
    untrained, _ = setup
    refused = tmp_path / "refused.onnx"
    assert export_cli.main(["--reseal", str(untrained), "--out", str(refused), "--sign", str(keys[0]),
                            "--threshold", "0.2", "--threshold-from", "x"]) == 2
    assert "no training record" in capsys.readouterr().err and not refused.exists()
    m = onnx.load(str(untrained))
    set_metadata(m, read_card(untrained).replace(training=TrainingRecord(10, 80, 0.1, 4, 1)))
    model = tmp_path / "trained.onnx"
    onnx.save(m, str(model))
    out = tmp_path / "rethresholded.onnx"
    args = ["--reseal", str(model), "--out", str(out), "--sign", str(keys[0])]
    assert export_cli.main([*args, "--threshold", "0.2", "--threshold-from", "real drives A, B"]) == 0
    before, after = onnx.load(str(model)), onnx.load(str(out))
    assert before.graph.SerializeToString() == after.graph.SerializeToString()
    engine, old = Engine(out), Engine(model)
    assert engine.threshold == engine.card.threshold == 0.2 != old.card.threshold
    assert engine.card.training is not None and engine.card.training.threshold_from == "real drives A, B"
    assert engine.card.self_test == old.card.self_test
    props = {p.key: p.value for p in after.metadata_props}
    assert json.loads(props["bsn.training"])["threshold_from"] == "real drives A, B"
    capsys.readouterr()
    for extra, says in ((["--threshold", "0.2"], "go together"), (["--threshold-from", "x"], "go together"),
                        (["--threshold", "0.2", "--threshold-from", " "], "may not be blank"),
                        (["--threshold", "1.2", "--threshold-from", "x"], "probability in (0, 1)")):
        assert export_cli.main(["--reseal", str(model), "--out", str(refused), "--sign", str(keys[0]), *extra]) == 2
        assert says in capsys.readouterr().err and not refused.exists()
    assert export_cli.main(["--checkpoint", "run", "--out", str(tmp_path / "r.onnx"), "--threshold", "0.2",
                            "--threshold-from", "x"]) == 2
    assert "give it with --reseal" in capsys.readouterr().err
    with pytest.raises(ValueError, match="where it was chosen"):
        export_cli.rethresholded(read_card(model), 0.2, "")


@pytest.mark.parametrize("where", ["before", "after"])
def test_a_card_holding_a_key_twice_is_refused_by_name(setup, tmp_path, keys, where):
    """A second 'bsn.threshold' beside the signed one: the runtime would read one, a tool listing the
    metadata would show both. Refused, the key named, before or after the signed entry."""
    model, _ = setup
    signed = signed_copy(model, tmp_path, keys[0])
    m = onnx.load(str(signed))
    entries = [(p.key, p.value) for p in m.metadata_props]
    twin = ("bsn.threshold", json.dumps(0.99))
    at = next(i for i, (k, _) in enumerate(entries) if k == "bsn.threshold") + (where == "after")
    entries.insert(at, twin)
    del m.metadata_props[:]
    for k, v in entries:
        e = m.metadata_props.add()
        e.key, e.value = k, v
    out = tmp_path / f"twice_{where}.onnx"
    onnx.save(m, str(out))
    with pytest.raises((ModelError, ValueError), match=r"holds the key 'bsn\.threshold' twice"):
        Engine(out, trust=TrustPolicy.default([str(keys[0]) + ".pub"], False))


def test_signing_a_signed_model_replaces_its_signature(setup, tmp_path, keys):
    """Re-signing (a key rotation, one's own signature on the shipped default) through the Python API: one
    signature entry afterwards, the new key's, which the runtime accepts; the old key's is gone."""
    from bsn_edge.export.signing import sign

    model, _ = setup
    ours, theirs = keys
    signed = signed_copy(model, tmp_path, ours)
    again = tmp_path / "again.onnx"
    sign(signed, theirs, again)
    entries = [p.key for p in onnx.load(str(again)).metadata_props if p.key == SIGNATURE_KEY]
    assert entries == [SIGNATURE_KEY], f"{len(entries)} signature entries after re-signing"
    assert Engine(again, trust=load_public_keys(f"{theirs}.pub")).authentic
    with pytest.raises(ModelError, match="not among the trusted keys"):
        Engine(again, trust=load_public_keys(f"{ours}.pub"))
    sign(again, theirs)                       # the same key twice, in place: still one entry, still valid
    assert [p.key for p in onnx.load(str(again)).metadata_props].count(SIGNATURE_KEY) == 1
    assert Engine(again, trust=load_public_keys(f"{theirs}.pub")).authentic
