"""What a training run reads: its clips split, the datasets over them, and the endless, resumable stream
of batches (from the sample cache, or sample by sample), with real pictures at a set share."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import torch
from torch.utils.data import DataLoader

from bsn_edge.data import BlindSpotDataset, Clip, find_clips, split_clips
from bsn_edge.data.cache import SampleCache, default_cache_root
from bsn_edge.data.guessed_camera import ClipCamera
from bsn_edge.labels.camvid import STYLE as CAMVID_STYLE
from bsn_edge.sequence import SequenceMeta
from bsn_edge.train.config import Config

REAL_STYLES = (CAMVID_STYLE,)   # clips of real pictures (data.real_share draws from them)


GROUP_SEED_STRIDE = 7919   # a group's permutations are drawn from seeds of their own, far from the others'


class BatchStream:
    """An endless, resumable stream of batches: ``[(sample index, augmentation seed), ...]``.

    Epoch ``e`` visits the samples in a permutation drawn from ``seed + e``; a global batch of
    ``batch x world`` samples is split between the ranks. Batch ``k`` of the stream depends only on
    ``k``, so a run resumed at step ``s`` sees exactly what an uninterrupted run sees from ``s`` on,
    augmentation included (each sample's seed is its position in the stream).

    With ``real`` (sample indices) and ``real_per_batch`` > 0, every global batch holds that many samples of
    ``real`` and the rest of the others, each group visited in permutations of its own (drawn from the
    seed and the group's pass over it), so a small group of real pictures is seen at a set share however
    many synthetic samples there are; batch ``k`` still depends only on ``k``.
    """

    def __init__(self, n: int, batch: int, seed: int, start: int = 0, world: int = 1, rank: int = 0,
                 real: tuple[int, ...] = (), real_per_batch: int = 0) -> None:
        self.n, self.batch, self.seed, self.start, self.world, self.rank = n, batch, seed, start, world, rank
        glob = batch * world
        self.per_epoch = max(n // glob, 1)
        self.glob = min(glob, n)
        if real_per_batch and not 0 < real_per_batch < self.glob:
            raise ValueError(f"real samples per batch must be within 1..{self.glob - 1}, got {real_per_batch}")
        if real_per_batch and not real:
            raise ValueError("real samples per batch were asked for, but there is no real sample")
        real_set = set(real)
        self.groups = ((tuple(sorted(real_set)), real_per_batch),
                       (tuple(i for i in range(n) if i not in real_set), self.glob - real_per_batch)) \
            if real_per_batch else ()

    @staticmethod
    def _take(members: tuple[int, ...], seed: int, start: int, count: int) -> list[int]:
        """``count`` members from position ``start`` of an endless run of permutations of ``members``
        (pass ``p`` drawn from ``seed + p``)."""
        out: list[int] = []
        pos = start
        while len(out) < count:
            p, j = divmod(pos, len(members))
            order = torch.randperm(len(members), generator=torch.Generator().manual_seed(seed + p)).tolist()
            got = [members[i] for i in order[j:j + count - len(out)]]
            out += got
            pos += len(got)
        return out

    def __iter__(self) -> Iterator[list[tuple[int, int]]]:
        k = self.start
        if self.groups:
            while True:
                glob = [i for g, (members, m) in enumerate(self.groups)
                        for i in self._take(members, self.seed + GROUP_SEED_STRIDE * g, k * m, m)]
                picked = glob[self.rank::self.world]
                yield [(i, (k * self.glob + r) * self.world + self.rank) for r, i in enumerate(picked)]
                k += 1
        while True:
            epoch, j = divmod(k, self.per_epoch)
            order = torch.randperm(self.n, generator=torch.Generator().manual_seed(self.seed + epoch)).tolist()
            for jj in range(j, self.per_epoch):
                lo = jj * self.glob
                picked = order[lo:lo + self.glob][self.rank::self.world]
                yield [(i, (epoch * self.n + lo + r) * self.world + self.rank) for r, i in enumerate(picked)]
                k += 1


def real_samples(ds) -> tuple[int, ...]:
    """The indices of ``ds``'s samples from real pictures (clips of a style in :data:`REAL_STYLES`)."""
    return tuple(i for i, (clip, _) in enumerate(ds.items) if clip.style in REAL_STYLES)


def stream_for(ds, n: int, batch: int, seed: int, start: int, world: int, rank: int,
               real_share: float) -> BatchStream:
    """The :class:`BatchStream` of ``n`` samples of ``ds``, with ``real_share`` of each global batch from
    its real pictures when it has any (0: every sample alike)."""
    real = real_samples(ds) if real_share > 0 else ()
    per = min(max(round(real_share * min(batch * world, n)), 1), min(batch * world, n) - 1) if real else 0
    return BatchStream(n, batch, seed, start, world, rank, real, per)


def batch_stream(ds, batch: int, world: int, rank: int, seed: int, workers: int, start: int = 0,
                 device: torch.device | None = None, real_share: float = 0.0) -> Iterator[dict]:
    """Batches of ``ds`` from stream position ``start`` on (see :class:`BatchStream`), on ``device``."""
    dl = DataLoader(ds, batch_sampler=stream_for(ds, len(ds), batch, seed, start, world, rank, real_share),
                    num_workers=workers,
                    pin_memory=device is not None and device.type == "cuda",
                    persistent_workers=workers > 0)
    # the iterator is made now, not at the first batch: it takes a draw from torch's generator, and a
    # resumed run restores that generator right after this call
    it = iter(dl)
    return it if device is None else (_to(b, device) for b in it)


def _to(batch: dict, device: torch.device) -> dict:
    return {k: v.to(device, non_blocking=True) if torch.is_tensor(v) else v for k, v in batch.items()}


def sample_cache(cfg: Config, ds, progress: bool = False, desc: str = "caching samples") -> SampleCache | None:
    """The decoded, warped samples of ``ds`` as ``data.cache`` asks (None when it is "off")."""
    where = cfg.data.cache
    if where == "off":
        return None
    root = None if where == "memory" else default_cache_root() if where == "auto" else Path(where)
    return SampleCache.for_dataset(ds, root, progress, desc)


def training_batches(ds, cache: SampleCache | None, batch: int, world: int, rank: int, seed: int, workers: int,
                     start: int = 0, device: torch.device | None = None, real_share: float = 0.0) -> Iterator[dict]:
    """The stream of :class:`BatchStream` as batches: gathered from ``cache`` (augmented as a batch),
    or loaded sample by sample from ``ds`` when there is no cache. Both give the same samples.
    ``real_share``: of each batch, from real pictures (``data.real_share``)."""
    if cache is None:
        return batch_stream(ds, batch, world, rank, seed, workers, start, device, real_share)
    stream = stream_for(ds, len(cache), batch, seed, start, world, rank, real_share)
    dev = device or torch.device("cpu")
    return (_to(cache.batch(picks, ds.augment, ds.seed, ds.object_repaint, ds.object_see_through, ds.camera_look),
                dev)
            for picks in stream)


@dataclass(frozen=True)
class Datasets:
    """What a training run reads: its clips split by clip (``clips``: train / val / test), the training
    clips after the style and fraction settings, the validation clips, the datasets over them, and
    the sequence folders found without usable labels (``(folder, reason)``)."""

    clips: dict[str, list[Clip]]
    train: list[Clip]
    val: list[Clip]
    skipped: list[tuple[str, str]]
    train_ds: BlindSpotDataset
    val_ds: BlindSpotDataset | None
    # the same samples warped with guessed cameras (data.guessed_camera > 0), else None
    train_guessed_ds: BlindSpotDataset | None = None
    val_guessed_ds: BlindSpotDataset | None = None


def datasets(cfg: Config, data_dir: str | Path) -> Datasets:
    """Clips split by clip, the training styles applied, and the datasets over them."""
    skipped: list[tuple[str, str]] = []
    clips = find_clips(data_dir, cfg.data.label, skipped=skipped)
    split = split_clips(clips, cfg.data.val_fraction, cfg.data.test_fraction, cfg.data.split_seed)
    train = split["train"]
    styles = cfg.data.train_styles
    if styles:
        train = [c for c in train if c.style in styles]
    if cfg.data.fraction < 1.0 and train:
        train = train[: max(1, round(cfg.data.fraction * len(train)))]
    if not train:
        raise ValueError(f"no training clips (styles {styles or 'any'}) in {data_dir}")
    if cfg.train.bce_range_m > 0:
        for c in train:
            meta = SequenceMeta.read(c.path)
            if not meta.rendered:
                raise ValueError(f"train.bce_range_m teaches B beyond the labels' V from exact depth, which only "
                                 f"rendered clips have: {c.path} was not rendered (its meta.json source is "
                                 f"{meta.source!r}); leave it at 0 for this data")
    val = [c for c in split["val"] if not styles or c.style in styles]
    camera, mounting = cfg.data.model_camera()

    def train_ds(cameras: ClipCamera) -> BlindSpotDataset:
        return BlindSpotDataset(train, cfg.data.size, augment=True, label_name=cfg.data.label, camera=camera,
                                mounting=mounting, seed=cfg.train.seed, object_repaint=cfg.data.object_repaint,
                                object_see_through=cfg.data.object_see_through, clip_camera=cameras,
                                camera_look=cfg.data.camera_look)

    def val_ds(cameras: ClipCamera) -> BlindSpotDataset | None:
        return BlindSpotDataset(val, cfg.data.size, label_name=cfg.data.label, camera=camera, mounting=mounting,
                                clip_camera=cameras) if val else None

    guessed = cfg.data.guessed_camera > 0
    return Datasets(split, train, val, skipped, train_ds(ClipCamera.OWN), val_ds(ClipCamera.OWN),
                    train_ds(ClipCamera.GUESSED) if guessed else None, val_ds(ClipCamera.GUESSED) if guessed else None)


def skipped_and_torn(data: Datasets, torn: list[Path]) -> dict[str, list[str]]:
    """What a training's summary says it left out: clips without usable labels, torn writes removed."""
    return {"skipped_clips": [f"{name}: {why}" for name, why in data.skipped],
            "removed_torn_writes": [str(t) for t in torn]}
