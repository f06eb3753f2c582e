"""Training samples decoded and warped once, kept as uint8 arrays: :class:`SampleCache`.

A training step of :class:`~bsn_edge.data.BlindSpotDataset` decodes four PNGs per sample and warps
them into the model camera. Over a campaign every frame is seen many times, so that work is done
once here and a step only gathers rows of arrays and augments the batch with tensor operations.

On disk (one folder per dataset, owned by this class; keyed by what the samples depend on)::

    CACHE/index.json       {"key", "size", "items": [[clip folder, frame], ...]}
    CACHE/rgb.npy          [N, H, W, 3] uint8, BGR as the frames are read
    CACHE/depth.npy        [N, H, W] uint16, metres x 256 (the sequence folder's depth encoding)
    CACHE/semantic.npy     [N, H, W] uint8 trainIds (255 ignore)
    CACHE/masks.npy        [N, H, W] uint8: bit 0 blind spot, bit 1 visibility
    CACHE/teacher_SHA.npy  [N, 2, C, gh, gw] float16: a teacher's pooled features, plain and flipped

Arrays are memory-mapped, so the page cache holds what RAM allows. A folder is written under a
temporary name and renamed when complete: a killed build leaves nothing that could be read as a
cache. ``folder=None`` keeps the arrays in memory (small datasets, tests).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import torch

from bsn_edge import semantics as sm
from bsn_edge.data.camera_look import CameraLook, camera_look, draw_camera_look
from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD, BlindSpotDataset
from bsn_edge.data.guessed_camera import ClipCamera
from bsn_edge.data.repaint import Repaint, SeeThrough, draw_repaint, draw_see_through, repaint, see_through
from bsn_edge.progress import progress_bar
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import DEPTH_SCALE, depth_to_png16

CACHE_VERSION = 1
ARRAYS = ("rgb", "depth", "semantic", "masks")
BLINDSPOT_BIT, VISIBILITY_BIT = 1, 2


def default_cache_root() -> Path:
    """Where sample caches live unless configured: ``$BSN_EDGE_CACHE``, else the user's cache folder."""
    env = os.environ.get("BSN_EDGE_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "bsn-edge" / "samples"


def dataset_key(ds: BlindSpotDataset) -> str:
    """What the samples of ``ds`` depend on: its items, size, model camera, clips' cameras, label set, and the
    size and time of every clip's metadata and label report (relabelling or re-rendering a clip
    changes them)."""
    h = hashlib.sha256()
    what = {"v": CACHE_VERSION, "size": list(ds.size), "label": ds.label_name,
            "camera": ds.camera.to_dict(), "mounting": ds.mounting.to_dict()}
    if ds.clip_camera is not ClipCamera.OWN:     # the clips' own cameras keep the keys of caches made before
        what["clip_camera"] = ds.clip_camera.value
    h.update(json.dumps(what, sort_keys=True).encode())
    seen: set[Path] = set()
    for clip, frame in ds.items:
        h.update(f"{clip.path.resolve()}:{frame};".encode())
        if clip.path in seen:
            continue
        seen.add(clip.path)
        seq = SequenceFolder(clip.path)
        for p in (seq.path / SequenceFolder.META, seq.labels(ds.label_name).report_path):
            st = p.stat() if p.is_file() else None
            h.update(f"{p.name}:{st.st_size if st else -1}:{st.st_mtime_ns if st else -1};".encode())
    return h.hexdigest()[:24]


class SampleCache:
    """The samples of a :class:`BlindSpotDataset`, decoded and warped once (see module docstring)."""

    INDEX = "index.json"

    def __init__(self, arrays: dict[str, np.ndarray], items: list[tuple[str, int]], key: str,
                 folder: Path | None = None) -> None:
        self.arrays, self.items, self.key, self.folder = arrays, items, key, folder
        self.teacher: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.items)

    @property
    def size(self) -> tuple[int, int]:
        return tuple(self.arrays["rgb"].shape[1:3])

    # -- building and opening --------------------------------------------------------------------

    @classmethod
    def for_dataset(cls, ds: BlindSpotDataset, root: str | Path | None, progress: bool = False,
                    desc: str = "caching samples") -> SampleCache:
        """The cache of ``ds`` under ``root`` (opened if built before, else built); in memory when
        ``root`` is None."""
        key = dataset_key(ds)
        if root is None:
            return cls._build(ds, key, None, progress, desc)
        folder = Path(root) / key
        if (folder / cls.INDEX).is_file():
            return cls.open(folder)
        return cls._build(ds, key, folder, progress, desc)

    @classmethod
    def open(cls, folder: str | Path) -> SampleCache:
        folder = Path(folder)
        index = json.loads((folder / cls.INDEX).read_text())
        arrays = {name: np.load(folder / f"{name}.npy", mmap_mode="r") for name in ARRAYS}
        n = len(index["items"])
        bad = [name for name, a in arrays.items() if a.shape[0] != n]
        if bad:
            raise ValueError(f"{folder}: sample cache damaged ({', '.join(bad)} do not hold {n} samples); "
                             "delete the folder to rebuild it")
        return cls(arrays, [tuple(i) for i in index["items"]], index["key"], folder)

    @classmethod
    def _build(cls, ds: BlindSpotDataset, key: str, folder: Path | None, progress: bool, desc: str) -> SampleCache:
        n, (h, w) = len(ds), ds.size
        shapes = {"rgb": ((n, h, w, 3), np.uint8), "depth": ((n, h, w), np.uint16),
                  "semantic": ((n, h, w), np.uint8), "masks": ((n, h, w), np.uint8)}
        tmp = None
        if folder is None:
            arrays = {name: np.empty(shape, dt) for name, (shape, dt) in shapes.items()}
        else:
            tmp = folder.with_name(folder.name + f".tmp{os.getpid()}")
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
            arrays = {name: np.lib.format.open_memmap(tmp / f"{name}.npy", "w+", dt, shape)
                      for name, (shape, dt) in shapes.items()}
        for k in progress_bar(range(n), desc=desc, unit="frame", enabled=progress and n >= 64):
            a = ds.load(k)
            arrays["rgb"][k] = a["rgb"]
            arrays["depth"][k] = depth_to_png16(a["depth"])
            arrays["semantic"][k] = a["semantic"]
            arrays["masks"][k] = ((a["blindspot"] > 0) * BLINDSPOT_BIT | (a["visibility"] > 0) * VISIBILITY_BIT)
        items = [(str(c.path), int(f)) for c, f in ds.items]
        if folder is None or tmp is None:
            return cls(arrays, items, key)
        for arr in arrays.values():
            arr.flush()  # type: ignore[attr-defined]  # open_memmap arrays: np.memmap
        del arrays
        (tmp / cls.INDEX).write_text(json.dumps({"key": key, "size": [h, w], "items": items}))
        try:
            tmp.rename(folder)
        except OSError:
            if not (folder / cls.INDEX).is_file():
                raise
            shutil.rmtree(tmp, ignore_errors=True)     # another process (a DDP rank) finished it first
        return cls.open(folder)

    # -- a teacher's features --------------------------------------------------------------------

    def attach_teacher(self, teacher: torch.nn.Module, scale: float, grid: tuple[int, int], batch: int = 16,
                       progress: bool = False, resize: Callable | None = None,
                       dtype: torch.dtype | None = None) -> None:
        """Compute (or load) ``teacher``'s decoder features pooled to ``grid``, for every sample as
        it is and flipped, so distillation needs no teacher pass per step. ``resize(x, scale)``
        brings a batch to the teacher's input scale; ``dtype`` runs it under autocast (the training's
        precision: bf16 where the CPU has it natively, many times faster than fp32 there)."""
        sha = hashlib.sha256(b"".join(v.detach().cpu().numpy().tobytes() for v in teacher.state_dict().values()))
        kind = "" if dtype is None else "_" + str(dtype).removeprefix("torch.")
        name = f"teacher_{sha.hexdigest()[:16]}_{scale:g}_{grid[0]}x{grid[1]}{kind}.npy"
        path = self.folder / name if self.folder is not None else None
        if path is not None and path.is_file():
            self.teacher = np.load(path, mmap_mode="r")
            return
        was_training = teacher.training
        teacher.eval()
        out = None
        with torch.no_grad():
            for lo in progress_bar(range(0, len(self), batch), desc="teacher features", unit="batch",
                                   enabled=progress and len(self) >= 64):
                idx = np.arange(lo, min(lo + batch, len(self)))
                img = self.images(idx, np.zeros(len(idx), bool), np.ones(len(idx)), np.zeros(len(idx)))
                both = torch.cat([img, img.flip(-1)])
                x = resize(both, scale) if resize is not None else both
                with torch.autocast("cpu", dtype=dtype or torch.float32, enabled=dtype is not None):
                    feats = teacher(x)[1]
                f = torch.nn.functional.adaptive_avg_pool2d(feats.float(), grid).numpy()
                if out is None:
                    out = np.empty((len(self), 2, *f.shape[1:]), np.float16)
                out[idx, 0], out[idx, 1] = f[:len(idx)], f[len(idx):]
        teacher.train(was_training)
        if out is None:
            raise ValueError("the sample cache is empty: no teacher features to compute")
        if path is not None:
            tmp = path.with_suffix(f".tmp{os.getpid()}.npy")
            np.save(tmp, out)
            tmp.replace(path)
            self.teacher = np.load(path, mmap_mode="r")
        else:
            self.teacher = out

    # -- batches ---------------------------------------------------------------------------------

    def images(self, idx: np.ndarray, flip: np.ndarray, gain: np.ndarray, bias: np.ndarray,
               paints: Sequence[Repaint | None] = (), semantic: torch.Tensor | None = None,
               throughs: Sequence[SeeThrough | None] = (), looks: Sequence[CameraLook | None] = ()) -> torch.Tensor:
        """Normalised RGB ``[B, 3, H, W]`` of samples ``idx``, flipped where ``flip``, with
        ``rgb * gain + bias`` clipped to [0, 1], the objects of ``semantic`` (as flipped) repainted
        by ``paints`` and seen through by ``throughs``, then each frame through its camera of ``looks``,
        when given (the dataset's augmentation, as a batch)."""
        bgr = np.asarray(self.arrays["rgb"][idx])
        bgr[flip] = bgr[flip][:, :, ::-1]
        x = torch.from_numpy(bgr).flip(-1).permute(0, 3, 1, 2).float().div_(255.0)   # RGB, [B, 3, H, W]
        g = torch.from_numpy(np.asarray(gain, np.float32))[:, None, None, None]
        b = torch.from_numpy(np.asarray(bias, np.float32))[:, None, None, None]
        x = (x * g + b).clamp_(0.0, 1.0)
        if any(p is not None for p in (*paints, *throughs)) and semantic is None:
            raise ValueError("repainting or seeing through objects needs the samples' semantics "
                             "(which pixels are objects)")
        if semantic is not None and any(p is not None for p in paints):
            x = repaint(x, semantic, paints)
        if semantic is not None and any(t is not None for t in throughs):
            x = see_through(x, semantic, throughs)
        if any(look is not None for look in looks):
            x = camera_look(x, looks)
        mean = torch.from_numpy(IMAGENET_MEAN)[None, :, None, None]
        std = torch.from_numpy(IMAGENET_STD)[None, :, None, None]
        return (x - mean) / std

    def evenly(self, frames: int, batch: int = 8) -> Iterator[dict[str, torch.Tensor]]:
        """Unaugmented batches of up to ``frames`` samples evenly spaced over the cache (validation)."""
        idx = np.unique(np.linspace(0, len(self) - 1, min(frames, len(self))).round().astype(int))
        for lo in range(0, len(idx), batch):
            yield self.batch([(int(k), 0) for k in idx[lo:lo + batch]], augment=False, seed=0)

    def batch(self, picks: Sequence[tuple[int, int]], augment: bool, seed: int,
              object_repaint: float = 0.0, object_see_through: float = 0.0,
              camera_look: float = 0.0) -> dict[str, torch.Tensor]:
        """The batch of ``picks`` (``(sample, draw)`` pairs, as the trainer's stream gives them), in
        the layout of :class:`BlindSpotDataset` items stacked, plus ``teacher_grid`` when a teacher
        is attached. Augmentation draws exactly what the dataset draws for the same ``draw``."""
        idx = np.array([k for k, _ in picks])
        n = len(idx)
        flip, gain, bias = np.zeros(n, bool), np.ones(n), np.zeros(n)
        paints: list[Repaint | None] = [None] * n
        throughs: list[SeeThrough | None] = [None] * n
        looks: list[CameraLook | None] = [None] * n
        if augment:
            size = tuple(self.arrays["rgb"].shape[1:3])
            for r, (_, draw) in enumerate(picks):
                rng = np.random.default_rng([seed, draw])
                flip[r] = rng.random() < 0.5
                gain[r], bias[r] = rng.uniform(0.8, 1.2), rng.uniform(-0.08, 0.08)
                paints[r] = draw_repaint(rng, object_repaint, size)
                throughs[r] = draw_see_through(rng, object_see_through, size)
                looks[r] = draw_camera_look(rng, camera_look, size)
        order = np.argsort(idx, kind="stable")                  # memory maps read faster in order
        back = np.empty(n, int)
        back[order] = np.arange(n)
        srt = idx[order]

        def gather(name: str) -> torch.Tensor:
            a = np.asarray(self.arrays[name][srt])[back]
            a[flip] = a[flip][..., ::-1]
            return torch.from_numpy(a.astype(np.int32) if a.dtype == np.uint16 else a)

        sem = gather("semantic")
        masks = gather("masks")
        out = {
            "image": self.images(idx, flip, gain, bias, paints, sem, throughs, looks),
            "depth": gather("depth")[:, None].float().div_(DEPTH_SCALE),
            "semantic": sem.long(),
            "blindspot": (masks & BLINDSPOT_BIT).bool()[:, None].float(),
            "visibility": (masks & VISIBILITY_BIT).bool()[:, None].float(),
            "sky": (sem == sm.SKY)[:, None],
        }
        if self.teacher is not None:
            t = np.asarray(self.teacher[srt])[back]
            out["teacher_grid"] = torch.from_numpy(np.where(flip[:, None, None, None], t[:, 1], t[:, 0])).float()
        return out
