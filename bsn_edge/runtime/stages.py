"""A frame's way through the runtime as a list of stage objects, each timed into ``stage_ms`` by the pipeline.

The way (:data:`STAGES`, the names the frame log, the summary and the report use): ``decode`` (the source's
frame, read on the feeder's thread: what it says is counted here), ``preprocess`` (the camera: online
calibration and the warp into the model camera, on the feeder's thread), ``visibility`` (the camera-health
check), ``inference`` (the model), ``postprocess`` (sectors and their alert state machines: the hazard
published to the send cycle), ``send`` (the cycles due, for a file's frames) and ``outputs`` (the overlay and
the maps, handed to their writers). A stage's :meth:`Stage.run` says whether the frame goes on; the pipeline
runs the rest only when it does, but a stage marked ``always`` (the send cycle) runs for every frame. Work done
on another thread (the feeder's decode and warp, an inference in flight) is counted at the seconds it took
there (:meth:`Stage.elsewhere`), not the time this thread waited for it.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from bsn_edge.alerts import AlertFrame, Hazard, SectorAlert
from bsn_edge.alerts.health import Fault, Status, SystemState
from bsn_edge.alerts.sectors import blind_spots
from bsn_edge.model_frame import ModelFrame
from bsn_edge.runtime.feeder import Prepared
from bsn_edge.runtime.frame_record import FrameRecord
from bsn_edge.runtime.sources import Captured
from bsn_edge.sequence.folder import frame_name

if TYPE_CHECKING:
    from bsn_edge.runtime.loop import FramePipeline

STAGES = ("decode", "preprocess", "visibility", "inference", "postprocess", "send", "outputs")
# what the outputs show of a frame before the bus has carried anything (a camera's first frames, before the
# heartbeat's first cycle): the bus has said nothing, so nothing is available
NOT_SENT = Status(SystemState.UNAVAILABLE, 0.0)


@dataclass
class Work:
    """One frame on its way: the feeder's prepared frame, its record, and what each stage leaves the next."""

    item: Prepared
    rec: FrameRecord
    inflight: Future | None = None          # its inference, started on an inference thread
    began: float = math.inf                 # when its inference began (perf_counter): its path's start at the latest
    infer_s: float = 0.0                    # the inference's own seconds, wherever it ran
    answer: tuple[np.ndarray, np.ndarray] | None = None    # probability and depth, finite
    mask: np.ndarray | None = None
    sent_at: float = 0.0                    # when its send stage ended (perf_counter)

    @property
    def cap(self) -> Captured:
        return self.item.cap


class Stage(ABC):
    """One step of a frame's way, over the pipeline's state (``p``): :meth:`run` does it and says whether the
    frame goes on."""

    name: ClassVar[str]
    always: ClassVar[bool] = False      # runs whatever the stages before it said

    def __init__(self, p: FramePipeline) -> None:
        self.p = p

    @abstractmethod
    def run(self, w: Work) -> bool: ...

    def elsewhere(self, w: Work) -> float | None:
        """The seconds this stage's work for ``w`` took on another thread, counted instead of this thread's
        time; None when it ran here."""
        return None


class Decode(Stage):
    """The source's frame: what the source says of it counted (drops, reconnects, a frame that did not decode,
    a frame of another size than its camera's); no picture to use ends the frame's way."""

    name = "decode"

    def run(self, w: Work) -> bool:
        return self.read(w.cap, w.rec)

    def elsewhere(self, w: Work) -> float | None:
        return w.cap.decode_s

    def read(self, cap: Captured, rec: FrameRecord) -> bool:
        """Count what the source says about this frame; False when there is no picture to use."""
        p, h = self.p, self.p.health
        p.frames += 1
        p.last_t = cap.t
        h.set_fault(Fault.DROPPED_FRAMES, p.dropped)   # live sources drop while we work
        h.set_fault(Fault.SOURCE_RECONNECTS, p.source.reconnects)
        if cap.frame is None:
            h.fault(Fault.DECODE_ERRORS)
            rec.fault = Fault.DECODE_ERRORS
            return False
        src = p.source
        if src.reconnects != p.reconnects_seen:    # a camera reopened may come back at another size
            p.reconnects_seen, p.shape = src.reconnects, None
        elif p.shape is None and p.frames == 1 and src.one_camera and src.size is not None:
            # the source's own size (a folder's: most of its first pictures'), not its first frame's
            p.shape = (src.size[1], src.size[0], 3)
        if p.shape is None or not src.one_camera:     # each picture its own camera, its own size
            p.shape = cap.frame.shape
        elif cap.frame.shape != p.shape:
            # a frame of another size (or aspect) than the source's is a damaged frame: warped as the
            # source's camera it would be stretched, so it is counted and not run
            h.fault(Fault.SIZE_CHANGES)
            rec.fault = Fault.SIZE_CHANGES
            return False
        return True


class Camera(Stage):
    """The camera: the frame shown to online calibration and warped into the model camera (on the feeder's
    thread, :meth:`FramePipeline.warp`); whether the levels come from a camera still calibrating."""

    name = "preprocess"

    def run(self, w: Work) -> bool:
        if w.item.mf is None or w.item.buf is None:
            return False
        self.p.health.calibrating(w.item.calibrating)
        return True

    def elsewhere(self, w: Work) -> float | None:
        return w.item.warp_s


class Visibility(Stage):
    """The camera-health check on the frame and what the model sees: its reason to the health (the send
    cycle's status) and to the frame's record."""

    name = "visibility"

    def run(self, w: Work) -> bool:
        p, cap = self.p, w.cap
        if cap.frame is not None and w.item.buf is not None:
            vis = p.visibility.look(cap.t, cap.frame, w.item.buf[0])
            p.health.camera(vis.reason)
            p.blind.add(cap.t, vis.reason)
            w.rec.visibility = vis
        return True


class Inference(Stage):
    """The model on the frame's input (or its answer from the inference thread it ran on), the input buffer
    given back to the feeder; an answer with NaN or infinity is counted and ends the frame's way."""

    name = "inference"

    def run(self, w: Work) -> bool:
        p, buf = self.p, w.item.buf
        if buf is None:
            return False
        prob, depth, w.began, w.infer_s = p.infer(buf) if w.inflight is None else w.inflight.result()
        if p.feeder is not None:
            p.feeder.release(buf)
        w.answer = self.checked(prob, depth)
        if w.answer is None:
            w.rec.fault = Fault.NAN_OUTPUTS
            return False
        return True

    def elsewhere(self, w: Work) -> float | None:
        return w.infer_s

    def checked(self, prob: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The model's answer; None (and counted) when it is NaN or infinity."""
        if not (np.isfinite(prob).all() and np.isfinite(depth).all()):
            self.p.health.fault(Fault.NAN_OUTPUTS)
            return None
        return prob, depth


class Sectors(Stage):
    """Mask and depth -> sector readings -> smoothed levels (each sector's alert state machine) -> the hazard,
    published to the send cycle (which decides the status it goes out with)."""

    name = "postprocess"

    def run(self, w: Work) -> bool:
        if w.answer is None or w.item.mf is None:
            return False
        unseen = w.rec.visibility.unseen if w.rec.visibility is not None else ()
        w.rec.hazard, w.mask = self.read(w.cap, w.item.mf, *w.answer, unseen)
        w.rec.bus_from = self.p.emitter.latest_from
        return True

    def read(self, cap: Captured, mf: ModelFrame, prob: np.ndarray, depth: np.ndarray,
             unseen: tuple[bool, ...] = ()) -> tuple[Hazard, np.ndarray]:
        """The hazard of one frame and its blind-spot mask; ``unseen``: the sectors the camera cannot see, said
        with their readings."""
        p = self.p
        mask = blind_spots(prob, p.engine.threshold, mf)
        readings = p.geometry.read(mask, mf.depth_to_metres(depth))
        sectors = []
        blind = unseen or (False,) * len(readings)
        for m, r, u in zip(p.machines, readings, blind, strict=True):
            score, level = m.update(cap.t, r.score)
            sectors.append(SectorAlert(score, level, r.distance_m, u))
        p.health.valid(cap.t, None if p.wall is None else p.wall())
        p.valid += 1
        hazard = Hazard(cap.t, tuple(sectors))
        p.emitter.publish(hazard)
        return hazard, mask


class Send(Stage):
    """The send cycles due by the frame's time (a file's: a live source's heartbeat sends its own), for every
    frame, whatever became of it."""

    name = "send"
    always = True

    def run(self, w: Work) -> bool:
        self.emit(w.cap)
        w.sent_at = time.perf_counter()
        return True

    def emit(self, cap: Captured) -> None:
        if not self.p.source.live:
            self.p.emitter.emit(cap.t)


class SideOutputs(Stage):
    """The overlay and the maps of a frame with a hazard, in the raw frame's pixels: its hazard with the
    status the bus carried (the last cycle sent), handed to each output still writing."""

    name = "outputs"

    def run(self, w: Work) -> bool:
        rec, mf = w.rec, w.item.mf
        if rec.hazard is None or mf is None or w.mask is None or w.answer is None:
            return False
        on_bus = self.p.emitter.last_sent()
        rec.status = on_bus.status if on_bus is not None else None
        self.write(w.cap, mf, w.mask, AlertFrame.of(w.cap.t, rec.hazard, rec.status or NOT_SENT), *w.answer)
        return True

    def write(self, cap: Captured, mf: ModelFrame, mask: np.ndarray, alert: AlertFrame, prob: np.ndarray,
              depth: np.ndarray) -> None:
        overlay, maps = self.p.sinks.get("overlay"), self.p.sinks.get("maps")
        if overlay is not None and overlay.ok:
            overlay.write(cap.index, cap.frame, mf, mask, alert)
        if maps is not None and maps.ok:
            maps.write(cap.index, cap.name or frame_name(cap.index, ""), mf, prob, depth)


WAY: tuple[type[Stage], ...] = (Decode, Camera, Visibility, Inference, Sectors, Send, SideOutputs)
