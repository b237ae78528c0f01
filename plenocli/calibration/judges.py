"""Which lattice the calibration vouches for, by which judge, and what hints may do.

Two judges look at the image independently (``verify``: the border autocorrelation at far lags
of a central crop; ``fold``: the whole central region folded onto the lattice). The border
judge decides when it can; when it cannot (smeared borders: compression, blur, Galilean
overlap), the fold judge may decide, provided the border judge does not contradict it (the
fold's lattice must have a positive border contrast, above its detuned control and above
every unrelated lattice the border judge looked at).

A hint (``--pitch``, ``--start``) only adds lattices for the judges to look at. It never
decides: every lattice the image alone proposes stays in the judgement, and the answer must
agree with the hint (pitch within 15 %; a start's kind, pitch within 15 % and angle within
5 deg) or the calibration is refused, saying what the image shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plenocli.calibration.candidates import Lattice
from plenocli.calibration.fold import Folds, FoldVerdict, fold_judge, nested_pairs, settle_fold
from plenocli.calibration.match import MatchVerdict, match_judge, match_measure, without_mosaic
from plenocli.calibration.search import (
    border_lattice,
    find_lattice,
    hypotheses,
    judged,
    refined,
    view_for,
)
from plenocli.calibration.verify import NULL_RATIO, Verdict, control_contrast, doubt, nested
from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import LATTICES, LensGrid

HINT_RANGE = 1.15               # a pitch hint admits lattices within 15 %
START_ANGLE_RAD = np.radians(5.0)  # a start's rotation admits lattices within 5 deg
FOLD_CANDIDATES = 5             # border hypotheses the fold judge looks at (best contrast)


@dataclass(frozen=True)
class Decision:
    """The lattice vouched for, the judge that decided ("border" or "fold") and both
    judges' findings (the fold judge's only when it was asked)."""

    lattice: Lattice
    judge: str
    border: Verdict
    fold: FoldVerdict | None = None
    match: MatchVerdict | None = None

    def to_dict(self) -> dict:
        return {"judge": self.judge, **self.border.to_dict(),
                "fold": self.fold.to_dict() if self.fold else None,
                "match": self.match.to_dict() if self.match else None}

    def describe(self) -> str:
        """Which judge decided and how close the rivals came."""
        if self.judge == "match":
            rival = self.match.rivals[0] if self.match.rivals else None
            return (f"match judge (border contrast only {self.border.contrast:.3f}, no sharp "
                    f"fold): the micro-images repeat their neighbours' content with "
                    f"median confidence {self.match.confidence:.3f}"
                    + (f", best rival {rival[0]} at {rival[1]:.3f}" if rival else ""))
        if self.judge == "border":
            rival = self.border.rivals[0] if self.border.rivals else None
            return (f"border judge: contrast {self.border.contrast:.3f}, control "
                    f"{self.border.control:.3f}" + (f", best rival {rival[0].describe()} "
                                                    f"at {rival[1]:.3f}" if rival else ""))
        fold = self.fold
        rival = fold.rivals[0] if fold.rivals else None
        return (f"fold judge (border contrast only {self.border.contrast:.3f}): "
                f"sharpness {fold.sharpness:.4f}, control {fold.control:.4f}"
                + (f", best rival {rival[0].describe()} at {rival[1]:.4f}" if rival else ""))


def decide(image: np.ndarray, all_views: dict, *, pitch_hint: float | None = None,
           start: LensGrid | None = None, cfa: str | None = None) -> Decision:
    """The lattice the judges choose on ``image`` (its views built by ``search.views``), or
    CalibrationError saying why none can be vouched for. Whether it contradicts a hint is
    :func:`check_hints`'s to say, once its lens centres are found too: a lattice refused
    there is not what the image shows (a scene's strong period can pass the border judge as
    another lattice, and a true --pitch would be called a contradiction)."""
    free = find_lattice(all_views, hypotheses(all_views, pitch_hint=None))
    own = None if start is None else Lattice(start.lattice, start.pitch_px, start.angle_rad)
    extra: list[tuple[Lattice, float]] = []
    if pitch_hint is not None and doubt(free):
        extra += find_lattice(all_views, hypotheses(all_views, pitch_hint=pitch_hint)).considered
    if own is not None and doubt(free):
        extra.append(refined(own, all_views))
    verdict = judged([*free.considered, *extra], all_views) if extra else free
    reason = doubt(verdict)
    decision = Decision(verdict.lattice, "border", verdict)
    if reason:
        try:
            decision = _fold_decision(image, verdict, extra, all_views, reason)
        except CalibrationError as err:
            if own is None and pitch_hint is None:
                raise
            decision = _match_decision(without_mosaic(image, cfa), verdict, own, pitch_hint,
                                       str(err))
    else:   # the fold judge checks the border judge's choice among nested relatives
        decision = cross_checked(image, decision, all_views) or decision
    return decision


def cross_checked(image: np.ndarray, decision: Decision, all_views: dict) -> Decision | None:
    """None when the fold judge does not contradict the border judge's lattice among its
    nested relatives (x2, /2, x sqrt(3) or sqrt(2) turned); else the fold judge's decision
    between them (confirmed as where the border judge has none), or CalibrationError. A
    scene periodic on a relative can mislead the border judge; the fold of the view that
    judged the lattice suffices to tell relatives apart."""
    chosen = decision.lattice
    precise = border_lattice(chosen, all_views)   # where the calibration will put it
    if np.isfinite(precise.pitch_err_px) and precise.lattice.same_as(chosen, rel=0.05,
                                                                     angle=0.05):
        chosen = precise.lattice
    view = view_for(chosen, all_views)
    folds = Folds.of_view(view.flat, view.factor)
    for coarse, fine, index in nested_pairs(chosen):
        truth = settle_fold(coarse, fine, index, folds)
        if truth is None or truth.same_as(chosen, rel=0.01, angle=0.01):
            continue
        reason = (f"the border judge chose {chosen.describe()}, the fold judge "
                  f"{truth.describe()}")
        contrast = view_for(truth, all_views).acf.contrast(truth)
        return _fold_decision(image, decision.border, [(truth, contrast)], all_views, reason)
    return None


def _fold_decision(image, verdict: Verdict, extra, all_views, reason: str) -> Decision:
    """The fold judge's decision where the border judge has none, or CalibrationError."""
    ranked = sorted((t for t in verdict.considered if np.isfinite(t[1])), key=lambda t: -t[1])
    candidates = [lat for lat, _ in [*extra, *ranked[:FOLD_CANDIDATES]]]
    if not candidates:
        raise CalibrationError(reason)
    fold = fold_judge(candidates, Folds(image, candidates[0].pitch_px))
    if fold.lattice is None:
        raise CalibrationError(f"{reason}; nor does the fold judge find one ({fold.reason})")
    acf = view_for(fold.lattice, all_views).acf
    contrast = acf.contrast(fold.lattice)
    control = control_contrast(fold.lattice, acf)
    others = [c for lat, c in verdict.considered if not _related(fold.lattice, lat, all_views)]
    if not (contrast > 0 and contrast >= NULL_RATIO * control
            and contrast > max(others, default=-np.inf)):
        raise CalibrationError(
            f"{reason}; the fold judge finds {fold.lattice.describe()} (sharpness "
            f"{fold.sharpness:.4f}) but the micro-image borders do not confirm it ("
            + (f"contrast {contrast:.3f}, control {control:.3f})" if np.isfinite(contrast)
               else "no border contrast can be measured there)"))
    border = Verdict(fold.lattice, contrast, verdict.rivals, control,
                     considered=verdict.considered)
    return Decision(fold.lattice, "fold", border, fold)


def _match_decision(image, verdict: Verdict, own: Lattice | None, pitch_hint: float | None,
                    reason: str) -> Decision:
    """The match judge's decision where neither other judge has one: on a start grid's
    lattice (its pitch and angle kept, its lens centre measured) or, with a pitch hint only,
    on the lattices near the hint (pitch, angle and centre measured); or CalibrationError."""
    ranked = [lat for lat, c in sorted((t for t in verdict.considered if np.isfinite(t[1])),
                                       key=lambda t: -t[1])]
    if own is not None:
        others = [lat for lat in ranked[:FOLD_CANDIDATES]
                  if not lat.same_as(own, rel=0.01, angle=0.01) and nested(own, lat) is None]
        found = match_judge(image, own, others)
        what = f"the start grid ({own.describe()})"
    else:
        near = [lat for lat in ranked
                if 1 / HINT_RANGE <= lat.pitch_px / pitch_hint <= HINT_RANGE]
        others = [lat for lat in ranked[:FOLD_CANDIDATES] if lat not in near]
        found = match_measure(image, pitch_hint, near, others)
        what = f"a lattice near the hinted pitch ({pitch_hint:g} px)"
    if found.lattice is None:
        raise CalibrationError(f"{reason}; nor does the match judge confirm {what}: "
                               f"{found.reason}")
    return Decision(found.lattice, "match", verdict, None, found)


def _related(lattice: Lattice, other: Lattice, all_views) -> bool:
    """Whether ``other``, or where its far border peaks put it, is ``lattice`` or nested with
    it."""
    precise = border_lattice(other, all_views)
    for lat in (other, precise.lattice) if np.isfinite(precise.pitch_err_px) else (other,):
        if lat.same_as(lattice, rel=0.01, angle=0.01) or nested(lattice, lat) is not None:
            return True
    return False


def within_hint(found: Lattice, pitch_hint: float | None) -> bool:
    """Whether ``found`` lies within HINT_RANGE of a pitch hint (or there is none)."""
    return pitch_hint is None or 1 / HINT_RANGE <= found.pitch_px / pitch_hint <= HINT_RANGE


def fits_start(found: Lattice, own: Lattice) -> bool:
    """Whether ``found`` has a start lattice's kind, its pitch within HINT_RANGE and its
    rotation within START_ANGLE_RAD."""
    step = LATTICES[found.kind]
    turn = abs((found.angle_rad - own.angle_rad + step / 2) % step - step / 2)
    return (found.kind == own.kind and 1 / HINT_RANGE <= found.pitch_px / own.pitch_px
            <= HINT_RANGE and turn <= START_ANGLE_RAD)


def check_hints(decision: Decision, pitch_hint: float | None, own: Lattice | None) -> None:
    """Refuse an answer that a hint contradicts, saying what the image shows: called only on
    a lattice vouched for (its lens centres found too)."""
    found = decision.lattice
    shows = f"the image shows a {found.describe()} lattice ({decision.describe()})"
    if not within_hint(found, pitch_hint):
        raise CalibrationError(f"--pitch {pitch_hint:g} contradicts the image: {shows}; pass "
                               f"--pitch {found.pitch_px:.1f} or drop --pitch")
    if own is not None and not fits_start(found, own):
        raise CalibrationError(f"the start grid ({own.describe()}) does not fit this image: "
                               f"{shows}; check the --start file or calibrate without it")
