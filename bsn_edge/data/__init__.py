"""Training data from labelled sequence folders."""

from bsn_edge.data.dataset import BlindSpotDataset, Clip, find_clips, split_clips

__all__ = ["BlindSpotDataset", "Clip", "find_clips", "split_clips"]
