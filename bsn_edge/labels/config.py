"""Parameters of T-frame blind-spot labels (BlindSpotNet, Section 3)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from bsn_edge.mounting import check_height

# The paper's minimum component area, 100 px, is for KITTI-size frames.
REF_AREA_PX = 100
REF_SIZE = (375, 1242)


@dataclass(frozen=True)
class LabelConfig:
    """How labels are made from a clip.

    rate:        label rate in frames/s; the clip is resampled to it (paper: 5).
    horizon_s:   T in seconds: road that becomes visible within this horizon counts (paper: 5 s).
    depth_tol:   l_d, metres: a warped road point whose aggregated depth agrees with frame t's
                 depth within this is visible, not hidden; 0 turns the filter off.
    vis_range:   L, metres: the visibility mask V is sky or a surface nearer than this (paper: 16).
    min_area:    components of the label smaller than this many pixels are dropped; ``None``
                 scales the paper's 100 px at 375x1242 with the image area.
    min_corr:    clips whose depth-to-landmark alignment correlation is below this are rejected.
    shrink_margin: subsampling safety factor of the forward warp (see ``warp.py``).
    camera_height: metres above the road, to put monocular VO in metres; ``None`` takes
                 meta.json's ``camera_height`` or 1.5 m.
    look_tol:    grey levels (0-255); > 0: a warped road point is also visible when it looks like
                 frame t's picture where it lands (window mean difference under this), for depth
                 and segmentation from models, whose own depth and classes cannot say it; 0: off
                 (exact depth and classes need no second opinion).
    users_unknown: road users (vehicles, people) with no road seen behind them in the later frames
                 are left out of V, unknown rather than taught as hiding nothing: for drives whose
                 frames are far apart (CamVid's, a second), where the road behind a road user is often
                 never in view of the few later frames; False: V as the paper.
    """

    rate: float = 5.0
    horizon_s: float = 5.0
    depth_tol: float = 1.0
    vis_range: float = 16.0
    min_area: int | None = None
    min_corr: float = 0.7
    shrink_margin: float = 0.5
    camera_height: float | None = None
    look_tol: float = 0.0
    users_unknown: bool = False

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"rate must be positive, got {self.rate}")
        if not self.horizon_s > 0:
            raise ValueError(f"horizon T must be positive, got {self.horizon_s} s")
        if self.horizon_frames < 1:
            raise ValueError(f"T = {self.horizon_s} s at {self.rate} frames/s spans no frame")
        if self.depth_tol < 0 or not self.vis_range > 0:
            raise ValueError("depth_tol (l_d) must be >= 0 and vis_range (L) positive")
        if self.min_area is not None and self.min_area < 0:
            raise ValueError(f"min_area must be >= 0, got {self.min_area}")
        if not -1.0 <= self.min_corr <= 1.0:
            raise ValueError(f"min_corr must be in [-1, 1], got {self.min_corr}")
        if self.camera_height is not None:
            check_height(self.camera_height, "camera_height")
        if not 0 <= self.look_tol <= 255:
            raise ValueError(f"look_tol must be in [0, 255] grey levels, got {self.look_tol}")
        if not 0 < self.shrink_margin <= 1:
            raise ValueError(f"shrink_margin must be in (0, 1], got {self.shrink_margin}")

    @property
    def horizon_frames(self) -> int:
        """T in label frames."""
        return round(self.horizon_s * self.rate)

    @property
    def name(self) -> str:
        """Folder name of these labels, e.g. ``T5s``."""
        return f"T{self.horizon_s:g}s"

    def min_area_px(self, height: int, width: int) -> int:
        if self.min_area is not None:
            return self.min_area
        return max(1, round(REF_AREA_PX * height * width / (REF_SIZE[0] * REF_SIZE[1])))

    def to_dict(self) -> dict:
        return {**asdict(self), "horizon_frames": self.horizon_frames, "name": self.name}
