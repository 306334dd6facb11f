"""A hover read from the take, corrected by reading the fitted model the same way.

Where a take does not record how far above the key the finger started, the loader reads it as
the fingertip's travel until the key moved (`features.approach_distance_m`). That reads long: by
the time the key has moved far enough to be seen, the pad has been compressed by the impact of
the key's mass and by the key's spring, more at higher speed (0.2-0.4 mm over a 4 mm hover on an
independent take). A model started that much too far from the key makes contact late in every
keystroke, and the misfit (0.03 mm there, four times the marker noise) reads as a discrepancy
that no effect explains.

The bias is the reading's, so the model that was fitted with the read hover is read the same
way: its predicted fingertip and key give a reading whose excess over the hover it was given is
the bias, and the hover is the reading less that excess. One correction suffices where the bias
changes slowly with the hover (on that take: 4.33 mm read, 4.07 mm corrected, 4.0 mm true; the
held-out systematic error 0.0298 mm before, 0.0077 mm after, against 0.0068 mm of noise).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pianobot.analysis.greybox.features import approach_distance_m
from pianobot.analysis.greybox.forward import MeasuredArm
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.physics.model import KeystrokeModel

#: The correction may remove at most this share of the read hover (a model far from the take,
#: as a base fit without a preload that holds the key, gives no trustworthy reading).
MAX_SHARE = 0.5


@dataclass(frozen=True)
class HoverCorrection:
    """The read hovers corrected (`batch`), and what changed (mm, for the notes)."""

    batch: KeystrokeBatch
    read_m: float  # median hover read from the take
    corrected_m: float  # median hover after the correction
    why: str = ""  # how it was corrected (default: by the fitted model's reading)

    def note(self) -> str:
        how = self.why or f"read the same way on the fitted model: {1e3 * self.corrected_m:.2f} mm"
        return f"{HOVER_NOTE_START} ({1e3 * self.read_m:.2f} mm) corrected for the pad's compression when the key starts to move, {how}"


#: How the note on a corrected hover starts (a later correction replaces the earlier note).
HOVER_NOTE_START = "the hover read from the take"


def read_hover(batch: KeystrokeBatch) -> bool:
    """Whether any keystroke's hover was read from the take (not recorded)."""
    return batch.has_motion and bool(np.isfinite(batch.distance_read_m).any())


def corrected_hover(batch: KeystrokeBatch, model: KeystrokeModel) -> HoverCorrection | None:
    """`batch` with its read hovers less the bias `model` shows when read the same way (None where
    nothing was read, or the model gives no usable reading)."""
    read = batch.distance_read_m
    mask = np.isfinite(read)
    if not (batch.has_motion and mask.any()):
        return None
    prediction = MeasuredArm.of(batch).predict(model)
    seen = replace(batch, x1_m=np.where(np.isfinite(batch.x1_m), prediction.x1_m, np.nan),
                   x2_m=np.where(np.isfinite(batch.x2_m), prediction.x2_m, np.nan))
    bias = approach_distance_m(seen) - batch.key_start_m - batch.distance_m  # as the loader reads it
    usable = mask & np.isfinite(bias)
    if not usable.any():
        return None
    typical = float(np.median(bias[usable]))
    one = np.ptp(read[mask]) == 0.0  # the loader read one hover for the take: one correction
    excess = np.full(batch.n, typical) if one else np.where(np.isfinite(bias), bias, typical)
    excess = np.clip(excess, 0.0, MAX_SHARE * np.where(mask, read, 0.0))
    if not (excess[mask] > 0).any():
        return None
    distance = np.where(mask, read - excess, batch.distance_m)
    return HoverCorrection(replace(batch, distance_m=distance), float(np.median(read[mask])),
                           float(np.median(distance[mask])))
