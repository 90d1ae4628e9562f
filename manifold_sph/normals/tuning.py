"""The tuning constants of normal estimation, in one place.

Every constant of :mod:`manifold_sph.normals` lives here, grouped by the step of
:func:`~manifold_sph.normals.estimate_normals` that reads it (the steps are described in
``docs/normals.md``, with the measurements that chose each value). The modules read them
as attributes of this module (``tuning.ROW_K``) at call time, so a study can change one for
a run (``monkeypatch.setattr(tuning, "SHEETS", False)`` in a test, or an assignment in a
benchmark) and restore it after.
"""

from __future__ import annotations

import numpy as np

# ----------------------------------------------------------------- public options
#: Orientation modes of :func:`estimate_normals` (a viewpoint (3,) is also accepted).
ORIENTATIONS = ("outward", "visible", "consistent", "none")

#: Normal estimators of :func:`estimate_normals`.
METHODS = ("jet", "pca")

#: Default number of nearest neighbours (itself included) of ``method="pca"``.
DEFAULT_K = 16

#: Default neighbours (itself included) of the jet fit, by degree: about twice the
#: number of coefficients.
DEFAULT_JET_K = {1: 10, 2: 16, 3: 20, 4: 30}

# ----------------------------------------------------------------- step 1: PCA frame
PCA_K = 10  #: neighbours of the first PCA normal (the frame of the jet fit)

# ----------------------------------------------------------------- step 2: jet fit
JET_WEIGHT = 4.0  #: base jet fits weigh neighbour j by exp(-JET_WEIGHT (r_j / r_k)^2), r_k the farthest

# ----------------------------------------------------------------- step 2b: rows taken for the surface
ROW_K = 32  #: neighbours searched for points steeply above and below the fitted plane
ROW_STEEP = 2  #: at least this many on each side (0 switches step 2b off)
ROW_TAN = 1.0  #: steep: height above the plane over the distance along it (1: 45 degrees)
ROW_LINE = 0.02  #: particles whose 10 nearest have a middle PCA eigenvalue below this fraction of the largest
ROW_K_LINE = 96  #: (on a line) are tested with this many neighbours

# ----------------------------------------------------------------- step 3: consistent orientation
ORIENT_K = 10  #: neighbours of the orientation graph
BRIDGE_K = 30  #: nearest neighbours searched for an edge to another k-NN component
BRIDGE_MAX_SIZE = 4096  #: components up to this size with no such neighbour are searched further
BRIDGE_MAX_LONELY = 256  #: at most this many of them
CUT_THIN = 0.5  #: tree edges where the reflection and parallel rules disagree (|n_i . n_j| above this) are doubtful (0: off)

# ----------------------------------------------------------------- step 4: winding-number check
TRUST = 0.9  #: spanning-tree edges below this confidence may separate patches
MAX_PATCHES = 400  #: at most this many patches (the most confident cuts are restored first)
MIN_PATCH = 8  #: smaller patches are merged back through their doubtful edges
MAX_PROBES = 6000  #: particles probed by the winding number (all of them up to this many)
PROBE_OFFSET = 1.0  #: probe distance over the local spacing
ROUNDS = 3  #: rounds of cutting and choosing the patch signs
CALIBRATE = True  #: divide the areas by the measured jump of the winding number across the particle
THICK_PROBE = 0.5  #: probes at most this fraction of the height of the point across a thin part (0: off),
THICK_FLOOR = 0.3  #: ... at least this fraction of the usual offset
THICK_PAR = 0.9  #: across: a point steeply off the tangent plane with |n_i . n_j| above this
THICK_NOISE = 12.0  #: ... and higher than this many noise levels
FLAG_S = 0.5  #: probes with w_in + w_out below this (both outside: a flipped thin part) start patches
FLAG_S_HIGH = 1.5  #: ... or above this (both inside: a flipped patch in a narrow gap; None: off)
HIGH_MIN = 12  #: both-inside regions of fewer particles (connected over the spanning tree) are not flagged
FLAG_S_EXPLAIN = 0.5  #: a both-inside patch flips only where that leaves at most this part of its excess S - 1

# ----------------------------------------------------------------- step 4: closed sheets (crossing surfaces)
SHEETS = True  #: closed sheets that cross others are judged by their own field
SHEET_DOT = 0.8  #: sheet edges: |n_i . n_j| above this
SHEET_TAN = 0.6  #: ... and each end within atan(this) of the other's tangent plane
SHEET_JUNCTION = 0.8  #: a junction: two of its sheet neighbours with |n_j . n_k| below this,
SHEET_SHAPE = 0.42  #: ... unless one shape operator explains their normals to this relative residual
SHEET_SUPPORT = 2  #: sheet edges lie in at least this many triangles of sheet edges
SHEET_PRUNE = 2  #: (pruned this many times)
SHEET_GROW = 30  #: rings over which left-out particles join a sheet (over sheet edges)
SHEET_MIN = 100  #: sheets have at least this many particles
SHEET_FRACTION = 0.005  #: ... and this fraction of the cloud
SHEET_CLOSED = 0.6  #: closed: |mean(w_in + w_out)| of a sheet's own field at least this
SHEET_NESTED = 0.95  #: ... unless this share of its probes lies inside the other sheets' field
SHEET_SEALED = 0.8  #: (wholly inside and sealed: |mean(w_in + w_out)| at least this)
SHEET_CROSS = 0.1  #: applied where a closed sheet has at least this share inside another
SHEET_MAX_JUNCTION = 0.25  #: and at most this share of the particles are junctions

# ----------------------------------------------------------------- step 5: feature-aware refit
REFIT_DOT = 0.7  #: neighbours kept by the refit: n_i . n_j above this
REFIT_ITERATIONS = 2  #: refit passes
SHARP_WEIGHT = 8.0  #: refit weight exponent where the fit residual is structured (bias, not noise)
SHARP_RHO = (0.55, 0.7)  #: full exponent below the first degree-3 / degree-2 residual ratio, base one above the second
SHARP_LINE = 0.25  #: base weights where the sharply weighted neighbours spread like a line (middle / largest eigenvalue)

# ----------------------------------------------------------------- step 6: degrees 3 and 4
GUARD_DEGREES = 3.0  #: a degree-3/4 normal within this angle of the degree-2 one is kept, or
GUARD_RESIDUAL = 0.25  #: ... one whose fit residual is below this fraction of the degree-2 fit's

# ----------------------------------------------------------------- step 7: consensus of undetermined directions
CONSENSUS_DEGREES = 20.0  #: reconsidered where the scale agreement is below cos of this
CONSENSUS_CANDIDATES = ((8, 1), (12, 2), (16, 2), (24, 2), (16, 1), (24, 1), (8, 0), (16, 0), (24, 0))  #: (k, degree; 0: PCA)
CONSENSUS_K = 12  #: neighbours (itself included) whose reflected normals vote
CONSENSUS_PRIOR = 0.05  #: bonus of the current normal (of a mean |cos| in [0, 1])
CONSENSUS_ROUNDS = 5  #: rounds of iterated conditional modes

# ----------------------------------------------------------------- step 8: visibility (orient="visible")
VIS_VIEWS = 48  #: viewpoints (Fibonacci sphere, 3 bounding radii out)
VIS_GAMMA = 1.0  #: hidden-point-removal flip radius 10**gamma times the farthest point
VIS_COS = 0.2  #: a normal is flipped where it makes less than -this with the mean direction to its viewpoints
VIS_MIN_VIEWS = 3  #: ... seen from at least this many

# ----------------------------------------------------------------- step 9: Voronoi poles (poles=True)
POLE_FITS = ((16, 2),)  #: step-7 candidates fitted in the pole frame (k, degree), besides the pole
POLE_JUMP = 0.3  #: the winding numbers at the two poles differ by more than this
POLE_ANTI = 0.2  #: ... and the two poles lie on opposite sides: -u1 . u2 above this

# ----------------------------------------------------------------- confidence
SCALE_K = (8, 20)  #: neighbourhoods of the scale term (a plane, a quadric)
SCALE_COS = (np.cos(np.radians(30.0)), np.cos(np.radians(10.0)))  #: its 0 and 1
THIN_K = 16  #: thickness term: the nearest point steeply across among these
THIN_NOISE = 4.0  #: ... and higher than this many times the cloud's noise level

# ----------------------------------------------------------------- k="auto": the scale that follows the noise
NOISE_K = 12  #: the noise level is read from degree-2 fits to the NOISE_K and 2 NOISE_K nearest
NOISE_REGION = 32  #: ... their residuals averaged (median) over this many nearest
NOISE_KURTOSIS = (1.9, 2.4)  #: residual kurtosis from which the residual counts as noise (0 below the first, 1 above the second)
NOISE_CLEAN = 0.15  #: below this relative noise (sigma / spacing) a cloud is clean: weighted fits on DEFAULT_JET_K
AUTO_K0 = 16  #: noisy regions: k = AUTO_K0 + AUTO_K_GAIN (sigma / spacing)^2,
AUTO_K_GAIN = 160.0  #: ...
AUTO_K_LADDER = (16, 20, 24, 32, 40, 48, 64, 80, 96)  #: ... rounded to one of these
SMOOTH_K = 16  #: noisy regions: normals averaged over this many nearest with a similar normal line
SMOOTH_DEGREES = 20.0  #: (the similarity weight exp(-((1 - |n_i . n_j|) / (1 - cos this))^2))

# ----------------------------------------------------------------- global orientation (patches.py)
TILT_NOISE = 1.0  #: edge tilts are read beyond this many noise levels over the edge length
SAFE_DOT = 0.85  #: safe edges: |n_i . n_j| above this
SAFE_TILT = 0.3  #: ... and tilts beyond the noise below this
UNSAFE_K = 16  #: unsafe particles: a point steeply across among this many nearest,
UNSAFE_STEEP = 0.7  #: ... its height above the tangent plane over its distance above this,
UNSAFE_NOISE = 3.0  #: ... and above this many noise levels;
UNSAFE_RESIDUAL = 2.0  #: or a fit residual above this many noise levels
PATCH_MIN = 20  #: patches of at least this many particles are signed by the winding number
PROBE_NOISE = 3.0  #: probes at least this many noise levels off the surface
ATTACH_K = 32  #: the rest: signs from the dipoles of this many nearest oriented neighbours
ATTACH_ROUNDS = 10  #: rings of the rest oriented from the oriented ones
REPAIR_ROUNDS = 3  #: rounds of the repair of regions whose probes read the field far from 1
REPAIR_MIN = 10  #: regions of at least this many particles
NOISY_SHARE = 0.5  #: the noisy path where at least this share of the particles reads noisy
NOISY_FRAME_K = 24  #: noisy path: the PCA frame of the fits on this many nearest

# ----------------------------------------------------------------- parts (shells.py)
#: Readings of a closed part inside another: its own part (normals out of it) or a cavity wall.
NESTED = ("separate", "cavity")
PART_CLOSED = 0.5  #: a part is closed where |mean(w_in + w_out)| of its own field is at least this
#: clean path: whole safe patches flipped where the field then counts whole parts (off: the eyes
#: through a head 1 -> 508 wrong of 800, measured)
CORRECT_PARTS = False
#: clean path: parts are also the sheets of shells.sheet_segments (closed parts that touch or cross
#: others; benchmarks/normals.py --only parts: character 0 95.34 -> 97.94 %, scene 0 94.87 -> 97.94 %,
#: scene 1 92.68 -> 93.35 % right signs)
PART_SHEETS = True
