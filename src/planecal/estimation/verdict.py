"""A verdict from one calibration (issue 31): how good this calibration is at the tool,
from its own samples, and whether a simpler level would have been better.

``assess`` judges a fit against the reference of ``estimation.reference`` (level 3's whole
model with the class's magnitudes, scaled by the samples' evidence): the calibration's
error at the tool point, pose by pose, is its tool point minus the reference's posterior,
a bias and a spread. From that:

* ``tool_mm``: the expected error, rms over the samples' poses (``accuracy``'s
  ``tool_point_mm``);
* ``band_mm``: the 10-90 % band of the position error ``planecal validate`` measures as AP
  near the samples (the worst of the 5 poses nearest the samples' middle), from draws of
  the reference's posterior;
* the simpler levels (offsets; full; full + compliance, as those levels fit them) refitted
  on the same samples to first order (``estimation.selection``) and judged by the same
  reference: where the calibration's estimate at the tool is not below a simpler level's,
  or its held-out residuals are above one's, it is ``worse`` than that level and
  ``refusal`` refuses it to every writer of a controller file (export, urdf, compensate)
  without --force;
* the ``grade``: ``worse``; ``good`` where the reference explains the samples at the noise
  model's level (its residuals within ``GOOD_NOISE`` x the noise) and the fit converged,
  so that the band holds; ``uncertain`` otherwise (errors beyond level 3's model: the band
  is then a lower bound).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.estimation.fit import linearized
from planecal.estimation.reference import Reference, build
from planecal.estimation.selection import SIMPLER, HeldOut, family_of

BAND = (0.1, 0.9)
NEAR = 5  # the poses the AP figure is judged at: the 5 nearest the samples' medoid
GOOD_NOISE = 2.0  # the reference's residuals within this x the noise model: the band holds
WHERE = ("the laser's beam point at its nominal standoff, in the robot's frame: rms over the "
         "calibration samples' poses; the band: the worst of the 5 poses nearest their "
         "middle (validate's AP)")


@dataclass(frozen=True)
class Comparison:
    """A simpler level on the same samples: its expected tool-point error and held-out
    residual rms [mm]."""
    level: str
    tool_mm: float
    held_out_mm: float


@dataclass(frozen=True)
class Verdict:
    level: str
    grade: str  # "good", "uncertain", "worse"
    tool_mm: float
    band_mm: tuple[float, float]
    held_out_mm: float
    fit_rms_mm: float
    comparisons: tuple[Comparison, ...]
    worse_than: tuple[str, ...]
    reasons: tuple[str, ...]
    scale: float
    noise_factor: float
    band_rms_mm: tuple[float, float] = (0.0, 0.0)
    where: str = WHERE

    def to_dict(self) -> dict:
        out = asdict(self)
        out["band_mm"] = list(self.band_mm)
        out["band_rms_mm"] = list(self.band_rms_mm)
        out["comparisons"] = [asdict(c) for c in self.comparisons]
        out["worse_than"] = list(self.worse_than)
        out["reasons"] = list(self.reasons)
        return out


def _near(points: np.ndarray, k: int = NEAR) -> np.ndarray:
    """The k poses nearest the medoid of the tool points (the point nearest all others)."""
    D = np.linalg.norm(points[:, None] - points[None], axis=-1)
    return np.argsort(D[int(np.argmin(D.sum(1)))])[:k]


def _band(ref: Reference, params) -> tuple[tuple, tuple]:
    """(AP band near the samples' middle, band of the rms over the poses) [mm]."""
    e = np.linalg.norm(ref.draws(params), axis=-1)  # (n, M)
    ap = e[:, _near(ref.points)].max(1)
    rms = np.sqrt(np.mean(e ** 2, 1))
    q = lambda v: tuple(float(x) * 1e3 for x in np.quantile(v, BAND))  # noqa: E731
    return q(ap), q(rms)


def _held_out_mm(res) -> float:
    lin = linearized(res)
    held = HeldOut(lin).residuals(np.ones(len(lin.names), bool), np.ones(len(lin.rp), bool))[0]
    return float(np.sqrt(np.mean(held ** 2)) * 1e3)


def simpler_levels(cal) -> list[CalibrationSettings]:
    """The simpler levels a calibration is judged against (``selection.SIMPLER``, as those
    levels calibrate: no geometry prior), with its fit options."""
    res, st = cal.result, cal.settings
    present = {family_of(res.layout, n) for n in res.layout.names_of(res.free)} - {None}
    prior = st.geometry_prior is not None
    return [CalibrationSettings(level="offsets" if not fams else "full",
                                compliance="compliance" in fams, options=st.options,
                                base_tolerance=st.base_tolerance)
            for _, fams, _ in SIMPLER
            if set(fams) < present or (set(fams) == present and prior)]


def assess(cal) -> Verdict:
    """The verdict (module docstring) of a ``calibrate.Calibration``."""
    res, st = cal.result, cal.settings
    pb = res.problem
    ref = build(res)
    tool, held = ref.rms_mm(res.params), _held_out_mm(res)
    comps = []
    for s in simpler_levels(cal):
        other = calibrate(pb.robot, pb.qe, pb.d_m, pb.initial, pb.plate, s, pb.direction,
                          pb.references).result
        comps.append(Comparison(s.label, ref.rms_mm(other.params), _held_out_mm(other)))
    worse = tuple(c.level for c in comps if tool >= c.tool_mm or held > c.held_out_mm)
    band, band_rms = _band(ref, res.params)
    label = st.label
    reasons = []
    for c in comps:
        if c.level in worse:
            what = (f"at the tool {tool:.3g} mm against {c.tool_mm:.3g}" if tool >= c.tool_mm
                    else f"held-out residuals {held:.4f} mm against {c.held_out_mm:.4f}")
            reasons.append(f"{label} is no better than {c.level} ({what})")
    if worse:
        grade = "worse"
    elif res.converged and np.sqrt(ref.noise_factor) <= GOOD_NOISE:
        grade = "good"
    else:
        grade = "uncertain"
        reasons.append("the fit did not converge" if not res.converged else
                       f"level 3's whole model leaves residuals {np.sqrt(ref.noise_factor):.1f}x "
                       "the noise model's: errors it does not describe, which the band "
                       "does not hold")
    return Verdict(label, grade, tool, band, held, res.rms_mm(), tuple(comps), worse,
                   tuple(reasons), ref.scale, ref.noise_factor, band_rms)


def refusal(doc: dict) -> str | None:
    """Why a result document must not reach a controller file, or None: its verdict found
    it worse than a simpler level (``assess``). The one check every writer of a controller
    file (export, urdf, compensate) calls; --force overrides it."""
    v = doc.get("verdict") if isinstance(doc, dict) else None
    if not isinstance(v, dict) or v.get("grade") != "worse":
        return None
    why = "; ".join(v.get("reasons") or []) or "worse than a simpler level"
    return (f"its calibration is worse than a simpler level: {why}; recalibrate at that "
            "level, or --force to write it anyway")
