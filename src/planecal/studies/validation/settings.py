"""The validation's settings (``planecal validate``'s options)."""
from __future__ import annotations

from dataclasses import dataclass

from planecal.base.errors import InputError

FORMAT = "planecal-validate/3"
# /1 (before issue 22) measured AP at the flange under ``ap_after_mm``: refused, not misread;
# /2 (before issue 31): one cube, no floors, an oracle without backlash (still reported)
OLD_FORMATS = ("planecal-validate/1", "planecal-validate/2")
# the nominal model, the validated one, its level's floor (``floors``: the best that
# level's model does), the twin's own whole true model
ROLES = ("before", "after", "floor", "oracle")
WHERE = ("tool", "flange")  # the laser's beam point at its measuring centre, the flange
# the near-sample cube (the keys without an infix, as before issue 31) and the standard's
# cube (ISO 9283's largest cube in the region the work uses: ``_standard``)
CUBES = ("", "_standard")
# the published figures the twin's are read against (docs/STUDIES.md, ERROR-MODEL.md 2.9)
ANCHORS = ("published after calibration: SCALAR 0.09 mm (simulation, three planes); KUKA "
           "Absolute Accuracy 1-3 mm -> 0.1-0.3 mm (vendor, secondary source); RoboDK "
           "0.05-0.15 mm with a laser tracker (not verified). The real MC70 (seed Table 9): "
           "max model error 0.10-0.19 mm on the plate after calibration (not an AP).")


@dataclass(frozen=True)
class ValidationSettings:
    cycles: int = 30
    cube_edge_m: float | None = None
    tcp_m: tuple | None = None  # a TCP in the flange frame besides the scene's (named "tcp")
    block_length_m: float = 0.100
    face_height_m: float = 0.040
    point_spacing_m: float = 0.020
    tilt_deg: float = 30.0
    distance_m: float = 0.080
    gauge_repeats: int = 10
    seed: int = 0
    clearance_m: float = 0.01
    gauge: bool = True  # the gauge-block test too (the demo and the breakdown skip it)
    standard_cube: bool = True  # the standard's cube too (the demo and the breakdown skip it)

    def check(self):
        if self.cycles < 2:
            raise InputError(f"--cycles must be at least 2, got {self.cycles}")
        if self.cube_edge_m is not None and not 0 < self.cube_edge_m <= 1.0:
            raise InputError(f"--cube-mm must be in (0, 1000], got {self.cube_edge_m * 1e3}")
        if not 0 < self.block_length_m <= 0.3:
            raise InputError(f"--block-mm must be in (0, 300], got {self.block_length_m * 1e3}")
        if self.gauge_repeats < 1:
            raise InputError("--gauge-repeats must be at least 1")


def figure_keys(role: str, cube: str = "") -> list[str]:
    """The JSON keys of one model's figures (``role`` one of ``ROLES``) in one cube
    (``CUBES``), each saying where (``WHERE``) and in which frame (none: the robot's;
    ``_cell``): AP and RP, worst of P1..P5, mm."""
    return [k for w in WHERE for k in (f"ap_{role}_{w}{cube}_mm", f"ap_{role}_{w}{cube}_cell_mm",
                                       f"rp_{role}_{w}{cube}_mm")]


FIGURE_KEYS = tuple(k for c in CUBES for r in ROLES for k in figure_keys(r, c))
