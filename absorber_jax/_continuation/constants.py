"""Numerical constants of the continuation: tolerances, patience and the band's fill."""

from __future__ import annotations

FORCING_PARAMETERS = ("omega", "amplitude")


KINDS = ("fold", "period_doubling", "neimark_sacker", "grazing")


# why a branch ended, and which of these mean it went where it was asked to: to a bound,
# back onto the branch it was switched from, or round a closed branch
TERMINATIONS = ("bounds", "rejoined", "closed", "max_points", "step_collapse", "grazing",
                "start_failed")
REACHED = ("bounds", "rejoined", "closed")


# grazing (rigid impacts): located when the orbit's closest approach to a wall is within
# this fraction of the wall's length scale (or its bracket in the parameter within it);
# the branch then resumes these fractions of the step beyond it (the first that converges
# to an orbit with the impact born there; then as far behind it, where the new branch
# folds back), or ends "grazing" where none does
GRAZING_TOL = 1e-11
GRAZING_STEPS = (0.05, 0.3, 1.0)
# a located grazing within this (relative) of one the branch passed already, in parameter
# value and state, closes a loop: the branch ends "closed"
LOOP_TOL = 1e-6
# a branch point within this fraction of an earlier chord's length off it (projecting
# inside it, going the same way) retraces the branch: it ends "closed" (driver._retraced)
RETRACE = 0.05
# ... on an earlier chord no more than this many times as long as the longer of its
# neighbours (steps grow by at most 1.5 from one point to the next: a longer chord spans a
# jump of the state at t = 0, an impact crossing t = 0)
RETRACE_SPIKE = 4.0
# branch points looked back over for the last one clear of the walls
GRAZING_LOOKBACK = 12
# samples per period of the orbit whose closest approach to the walls is measured (each
# apex of its flights then refined by the cubic Hermite interpolant of its interval)
GRAZING_SAMPLES = 4096
# a rigid branch creeping towards a grazing impact (driver._crawling): over this many points
# its largest |multiplier| grows at every point to at least CRAWL_MULTIPLIER while its
# parameter steps shrink; the grazing is then extrapolated on the fixed sequence of events,
# no farther than CRAWL_REACH times the last parameter step
CRAWL_POINTS = 8
CRAWL_MULTIPLIER = 50.0
CRAWL_REACH = 50.0
# ... and that close integration is skipped where the corrector's own samples put every free
# flight farther than this from the walls (relative to the motion's length scale; their
# apexes are within ~1e-9 of it: see driver._approach)
APPROACH_MARGIN = 1e-6


# a bifurcation located by one half-branch of a band cell is taken by the other, which saw it
# too, where it lies on that one's bracket: projected onto the chord between the bracket's
# ends, between them, and no farther from the chord than this fraction of its length (the
# orbit's state at t = 0 and the parameter, each over its largest magnitude)
CHORD_SAG = 0.1

# a bifurcation is located when the regula-falsi correction or its bracket has shrunk to
# locate_tol and the test function there is this small against its values at the bracket's
# first ends (else it jumps there)
JUMP_TOL = 1e-3


# band_continuation's first guesses at a start value: the linear response scaled by these
# (near a resonance the linear response can be far larger than the impacting orbit: on the
# Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py Newton from it fails at 29.4
# and 35.9 rad/s)
START_SCALES = (1.0, 0.3, 0.1)


# band_continuation's starts where no scaled linear response converges: first guesses from
# the CLOSE_RETURNS closest returns of a trajectory marched CLOSE_RETURN_PERIODS periods (the
# first CLOSE_RETURN_SKIP left out as transient).  Six rather than three: on the hard rigid
# band of scripts/benchmark_rigid_impacts.py the parts no branch reached shrank from 0.50 to
# 0.11 rad/s (the fill passes' starts in its chaotic windows found orbits), for 19 -> 27 s
CLOSE_RETURN_PERIODS, CLOSE_RETURN_SKIP, CLOSE_RETURNS = 240, 40, 6


# band_continuation's fill passes start new branches in the parts of the band no branch
# reached that are wider than this fraction of it
GAP = 1e-4


# a first orbit's Newton (from a far guess) is given up once its residual has grown this
# many times over the least so far: on the hard-contact scenes of
# scripts/benchmark_hard_contacts.py, Newton from the guesses that fail diverges from its
# first steps (the Hertz band's fill passes: residuals from ~1 to 1e2-1e6 in 12 steps, each
# step dearer as the iterate's motion grows, 47 s of its 102 s), while the guesses that
# succeed decrease the residual at every step
PATIENT_GROWTH = 10.0

# a rigid-impact corrector's point must close on the statistics' own integration of its
# orbit within this many corrector tolerances (the two integrations differ by the
# integrator's error amplified by the orbit's multipliers: ~1e-13 in closed form; a step
# across a grazing leaves ~1e-3)
CLOSURE = 100.0


# a branch's Poincaré section moves (Driver.resection) where the clearance to the nearest
# contact wall there has fallen below RESECTION of the best on the orbit, and not where
# the tangent's parameter component (which orients the tangent in the new section) is below
# RESECTION_TANGENT
RESECTION, RESECTION_TANGENT = 0.5, 1e-3


# ... and keeps the point re-solved there only where its state at t = 0 is the point's to
# this fraction of the orbit's size (at rtol 1e-7 the hard-contact orbits' states at t = 0,
# mapped from two sections, differ by up to ~1e-2 where the absorber is in contact)
RESECTION_SAME = 5e-2


# a sharp turn of the tangent is accepted as a corner once the step is reduced this much
CORNER_REDUCTION = 16.0
