"""Normals for clouds that have none: fitted, oriented consistently and outward.

Pipeline of :func:`estimate_normals` (default ``method="jet"``, ``degree=2``; steps 2b,
5 and 7 with ``refine=True``, the default; step 8 with ``orient="visible"``, step 9 with
``poles=True``):

1. **PCA** on the ``min(k, 10)`` nearest neighbours gives a first, unsigned normal
   (the eigenvector of the smallest eigenvalue of the local covariance; all ``N``
   3x3 eigenproblems in one batched ``eigh``).
2. **Jet fit** (Cazals & Pouget 2005). In the tangent frame of that normal the
   ``k`` neighbours are fitted by a height function ``z = sum c_ab x^a y^b`` of
   total degree ``d`` (weighted least squares, all ``N`` small systems solved at
   once); the normal is that of the fitted surface at the particle. With the default
   ``k`` (16 at degree 2) neighbour ``j`` weighs ``exp(-4 (r_j / r_k)^2)``, ``r_k`` the
   distance to the farthest (scale-free, so the order is kept; an explicit ``k``, e.g. a
   larger one for noisy clouds, fits with uniform weights). Against the former uniform
   fit on the 12 nearest (full pipeline, median angle to the mesh normals and normals
   more than 30 degrees off): cow 6.15 -> 5.47 deg, 238 -> 227; teapot 2.63 -> 2.33,
   663 -> 637; cheburashka 1.33 -> 1.25, 205 -> 183; beetle 10.40 -> 8.88, 186 -> 155;
   mean error on a Poisson torus of 2000 / 8000 points 0.25 / 0.062 -> 0.19 / 0.047 deg;
   a sphere with noise of 0.1 / 0.3 spacings 2.49 / 8.31 -> 2.60 / 7.51 deg (a weight of
   8 was better on clean models and worse with noise: 3.99 / 12.55). On a smooth
   surface the normal error is ``O(h^d)`` (PCA: ``O(h)``), so ``degree=3`` or ``4``
   (with more neighbours) gives third and fourth order.
2b. **Rows taken for the surface.** A fitted plane normally has the nearby points
   of the surface close to it (heights of order ``kappa r^2``). Where at least 2 of the
   32 nearest lie more than 45 degrees above it AND 2 below, the fit saw one row of a
   cloud sampled along planar curves (the meridian rows of a surface of revolution,
   scan lines, a rolled lip a dozen points around) and returned the plane of the row.
   The candidate normal is perpendicular to the row (the direction to the nearest
   neighbour) and to the nearest steep point on each side (the adjacent rows); it
   replaces the fit where it at least halves the smaller steep count. Particles whose
   10 nearest lie on a line (middle PCA eigenvalue below 0.02 of the largest) are
   tested again with their 96 nearest (rows denser than 32 points between rows; a
   torus on 12 meridian circles of 80 points: 960 -> 506 normals more than 30 degrees
   off, so still short there). The refit of step 5 keeps these normals (their nearest
   neighbours lie on their own row); step 7 may reconsider them. Not kept: protecting
   them there too (teapot 94 instead of 138 normals more than 30 degrees off, but cow
   2.6 instead of 2.2 % inward), or only those with no point steeply on both sides of
   their plane (teapot 136 -> 98, but 3 of 640 inward on the meridian torus of the
   tests, and the cow's confidence missed 39 instead of 32 doubtful normals). Teapot
   (its lip and meridian rows): 630 -> 138 normals more than 30 degrees off, 90.1 ->
   98.3 % agreeing with the mesh; cow 231 -> 209; a thin torus sampled on 40 meridian
   circles of 16 points 281 / 343 -> 37 / 2 (seeds 0, 1); analytic clouds (spheres,
   tori, the ring sphere) never trigger it.
3. **Consistent orientation.** On the k-nearest-neighbour graph, the sign across
   an edge ``(i, j)`` is predicted by reflecting ``n_i`` in the bisector plane of
   ``p_i p_j`` (the normal a circle through both points tangent to ``n_i`` has at
   ``p_j``; König & Gumhold 2009) and compared with ``n_j``; the edge confidence is
   ``|n_j . R n_i|``. Unlike Hoppe's ``|n_i . n_j|`` this is right across thin
   parts (opposite sides of a thin sheet are reflections of each other) and across
   symmetric creases. Signs are propagated over the maximum-confidence spanning
   tree by pointer jumping (no loop over particles). Where the k-NN graph falls
   apart (clouds sampled much more densely along lines than across them: scan lines,
   the rings of a surface of revolution), each particle with another component among
   its 30 nearest is also joined to the nearest such particle, and small components
   with none to their nearest outside particle, so that bands of lines are oriented as
   one surface (a latitude-ring-sampled sphere without its polar caps: 80-160 of 800
   normals inward before, none after; tests/test_normals.py).
   **Noise is not a thin part.** The reflection rule reads an edge that leaves the tangent plane
   steeply as a step across a thin part; on a noisy cloud noise tilts edges so, and the
   spanning tree carried confident wrong signs into whole regions (the planar alligator's vertices
   with noise of 0.3 spacings: a third flipped; the teapot's lid). Tree edges where the reflection
   rule and the parallel rule (the sign of ``n_i . n_j``, with ``|n_i . n_j| > 0.5``) disagree are
   therefore treated as doubtful: patches are cut there, and step 4's winding number decides
   (``python benchmarks/normals.py --noisy``, the models' vertices with noise of 0.1 and 0.3
   spacings, seeds 0 and 1, wrong normals in all 3,270 -> 1,568 on the test models and the bunny,
   19,259 -> 15,806 with the extra spot, suzanne, beetle-alt, woody and beast: alligator 1089 -> 3,
   teapot 652 -> 198, beetle 134 -> 38, beast 3921 -> 2432, homer 74 -> 51 / 87 -> 59; worse:
   teapot 60 -> 72 at 0.1, beast 1912 -> 2381 at 0.1 with seed=1, cow 111 -> 112). Noise-free vertex clouds: the same but the
   teapot 40 -> 43 and the extra beast 2400 -> 2300; random samples (seeds 0-3, all models and the
   extra ones) 2716 -> 2608 in all; a closed slab half a spacing thick (hopeless either way) 537 /
   473 -> 589 / 527 inward of 2000, one spacing thick 160 / 86 -> 151 / 86.
4. **Global check with the generalised winding number** (Barill et al. 2018; the
   idea of Xu et al. 2023). For outward normals the winding number
   ``w(q) = sum_j a_j n_j . (p_j - q) / (4 pi |p_j - q|^3)`` of the oriented cloud
   is 1 just inside the surface and 0 just outside, so at the probes
   ``q = p_i -+ delta_i n_i`` one wants ``w_in = 1`` and ``w_out = 0``. The cloud is
   cut into patches (spanning-tree pieces separated by doubtful edges, and by
   particles whose probes disagree), and the patch signs minimise
   ``sum_i a_i [(w_in - w_out - 1)^2 + (w_in + w_out - 1)^2]`` (the field is linear
   in the patch signs, so this is a small quadratic problem in +-1 variables,
   solved by greedy single-patch and whole-component flips). This repairs what
   propagation gets wrong (thin parts, shells that touch) and orients every shell,
   closed or open, outward. Particles whose probes give ``w_in + w_out < 0.5`` (both
   probes outside: a flipped thin part; was ``< -0.5``) are cut into patches of their
   own: cow 2.17 -> 1.58 % inward (on the tail 48 -> 29 wrong), teapot 98.30 -> 97.81 %
   agreeing, cheburashka 0.87 -> 0.90 %. Before the signs are chosen the areas
   ``a_i = pi r_8^2 / 7.5`` are divided by the measured jump ``|w_in - w_out|`` (median
   over the 10 nearest, clipped to [1, 4]; the far field cancels in the difference, so
   the jump is the local dipole density over the true one whatever the orientation):
   on a ring-sampled sphere the 8 nearest lie on one ring, the areas were too large on
   the wide rings, the field inside overshot 1 and flipping the small polar rings
   lowered the objective (160 of 960 inward; now none). Areas are only reduced: in a
   noisy layer the probes sit among the points and the jump is too small (enlarging
   areas by it flipped 153 of 4000 normals on a torus with noise of 0.3 nearest-neighbour
   spacings, none now; clipped to [1/4, 4] the models read cow 1.58 % inward instead of
   1.72, cheburashka 0.90 instead of 1.02, teapot 97.8 % agreeing instead of 98.6).
   In thin parts the probes stay inside: the offset ``delta_i`` is at most half the height
   ``t_i`` of the nearest of the 16 nearest points that lies steeply across the tangent plane
   (more than 45 degrees off it) with a nearly parallel normal (``|n_i . n_j| > 0.9``) and
   higher than 12 noise levels (the cloud's median relative jet-fit residual times the
   distance to the 16th nearest), and at least 0.3 of the usual offset. With the exact
   (mesh) directions, steps 3-4 alone left 30 of the cow's normals inward, 25 of
   cheburashka's and 34 of the teapot's disagreeing with the mesh; with probes at half the
   height across (no other condition) 4, 1 and 4. In the pipeline (default, normals inward
   or disagreeing): cheburashka 68 -> 45 (1.02 -> 0.67 %), teapot 45 -> 39 (98.61 -> 98.80 %
   agreeing), cow 50, beetle 33, homer 1, rocker-arm 0, spot 3 and suzanne 30 unchanged (the
   cow's and the beetle's are direction errors: with the pre-refit directions of step 4 the
   thin parts have no parallel point across). Without the parallel-normal condition suzanne
   went 30 -> 42, without the floor 45; with 6 or 8 instead of 12 noise levels noisy random
   spheres (noise of 0.3 spacings) had 1-2 more normals inward; a thin slab (flat ellipsoid)
   is not helped (its straddling fits read as noise; see step 8).
   **Both probes inside.** Propagation can carry a wrong sign into a whole patch over
   confident tree edges (on area-uniform random samples, where a few long edges join a narrow
   gap with the rest); its probes then read ``w_in + w_out`` about 2 (the outer probe lies in the
   gap, inside the surrounding surface), which neither flag above catches, so the patch stayed
   merged with the right part (homer, 6002 random points, seed=1: 49 of its 71 inward normals
   were one such patch, 74 % of its directions within 30 degrees). Probes with ``w_in + w_out >
   1.5`` therefore form a third class, cut from both others, where such a region (connected over
   the spanning tree) holds at least 12 particles; and a patch of this class is flipped only where
   the flip removes at least half of its excess ``w_in + w_out - 1`` (a flipped patch in a gap:
   nearly all; a part inside another shell, such as the teapot's body wall inside its spout, reads
   both inside either way and keeps its propagated sign: without this condition 96 instead of 70
   disagreeing normals on the teapot's random seed=0 sample). Random samples (``benchmarks/normals.py
   --random``, wrong signs, seeds 0-7 before -> after): homer 6 / 71 / 22 / 24 / 9 / 6 / 67 / 43 ->
   6 / 8 / 22 / 24 / 9 / 6 / 2 / 4, cheburashka 48 -> 47 (seed=1) and 56 -> 59 (seed=5), all other
   models and seeds unchanged (cow, rocker-arm, teapot, beetle, alligator; seeds 0-3 of spot,
   suzanne, beetle-alt, woody); beast (32,311 points) 379 / 613 / 430 / 426 -> 354 / 382 / 430 / 335. The
   vertex clouds of the models, the synthetic clouds of the benchmark and noisy random spheres and
   tori are unchanged (nothing triggers), but the beast, 91.1 -> 92.6 % agreeing. Tried and not
   kept: all both-inside regions (no size floor: homer seeds 2 and 3 22 -> 13 and 24 -> 12, but the
   cow's vertices 51 -> 60 inward, cheburashka 45 -> 52, teapot 40 -> 52 disagreeing; the objective
   prefers those wrong signs, so comparing its minima does not help); a floor of 4-8 (cow 61).
   **Surfaces that pass through each other.** Closed parts of a model that interpenetrate (an
   artist's character with its eyes and teeth, an assembly) read both inside where one lies inside
   the other, and the patch check flipped those parts (two spheres through each other: 1037-1109 of
   6560 wrong). The cloud is therefore cut into sheets: k-NN edges whose ends lie within
   ``atan(0.6)`` of each other's tangent plane with ``|n_i . n_j| > 0.8``, without junctions and
   without edges in fewer than 2 triangles of sheet edges (bridges). A junction is a particle two
   of whose sheet neighbours are not parallel (``|n_j . n_k| < 0.8``: a normal averaged over both
   surfaces) unless one shape operator explains its neighbours' normals (the tangent part of
   ``n_j`` fitted as ``S (p_j - p_i) + c`` with a symmetric ``S``, to a residual below 0.42 of their
   spread: on one strongly curved surface the normal turns linearly with the position, across a
   crossing it jumps; without this, small teeth 3 spacings in radius were all junctions). Sheets
   of at least 100 particles (and 0.5 % of the cloud) keep their label; left-out particles
   (junctions, small pieces) join the sheet of a neighbour over a sheet edge, over up to 30 rings.
   Each sheet is then oriented on its own edges (the propagation over the whole graph may have
   mixed its signs where it crosses another) and is closed where its own field is decisive
   (``|mean(w_in + w_out)| >= 0.6``). A closed sheet wholly inside the others (95 % of its probes)
   and sealed (``>= 0.8``) is the inner wall of a hollow part and keeps the whole field (it faces
   the cavity, as before); one inside but open has lost its outside part where it crosses another
   surface (an eye whose outer cap joined the head's sheet) and stays closed. Where at least two
   closed sheets exist and one has at least 10 % of its probes inside the others' field, the
   probes of every closed sheet see only their own sheet's patches, and patches do not cross
   sheet borders. Nothing changes where more than 25 % of the particles are junctions or where no
   closed sheet crosses another (the random samples of cheburashka have pieces reading up to 7 %
   inside: 0.5 % flipped 75 more of their normals). ``python benchmarks/normals.py --crossing``
   (wrong normals, seeds 0-2, random and Poisson samples, noise 0 and 0.1 spacings, sheets off ->
   on): two spheres (6560) 1037-1109 -> 0-28; three spheres (8000) 1647-1797 -> 2-45, but 685 on one
   seed (the third sphere's cap inside the first is a sheet of its own, open, and follows the whole
   field); a torus through a sphere (7000) 1152-1228 -> 4-82; unequal spheres with a large overlap
   mostly unchanged (0-1526); a head of 12,000 points with two eyes half out of it (400 points each)
   and six teeth across its surface (150 each) 1081-1198 -> 50-646 (Poisson, noise-free: 50 / 56 /
   256; the eyes from 480-521 to 0-16 of 800 in 10 of the 12 runs, the teeth from about 400 to
   31-453 of 900); never worse. Nested spheres: unchanged (the inner one faces the cavity). The
   vertex tables are the same but the teapot, whose lid and body cross (43 -> 50 of 3241
   disagreeing), the random samples of every model and the synthetic table the same bit for bit.
   The winding number is summed with a two-level cell
   approximation (exact near, one dipole per cell and patch far). A patch with no
   evidence either way (a flat sheet) is oriented so that its mean normal has a
   positive largest component.
5. **Feature-aware refit.** Each particle is refitted using only the neighbours
   whose oriented normal is within about 45 degrees of its own
   (``n_i . n_j > 0.7``), twice: no averaging across a crease or across a
   thin part, and the full neighbourhood (so the full order) on smooth parts.
   With the default ``k = 16`` the row of particles next to a cube edge keeps a
   median error of about 26 degrees (PCA: 33); ``degree=3`` (``k = 20``) gets
   all of them within 5 degrees (measured, tests/test_normals.py).
   Where too few neighbours remain for the degree, a plane is fitted.
   **Sharper weights where the residual is bias.** The refit's Gaussian weights
   ``exp(-alpha (r_j / r_k)^2)`` use ``alpha`` from 4 up to 8 per particle: the base
   neighbourhood is also fitted at degree 3, and where the ratio of the degree-3 to the
   degree-2 residual (median over the neighbours) is below 0.55 the residual is structure
   (a coarsely sampled, strongly curved part: the neighbourhood is too wide) and the exponent
   is 8; above 0.7 it stays 4 (noise reads about 0.8: 0.68-0.76 at the 10th percentile on
   spheres with noise of 0.01-0.3 spacings), linear between; where the sharply weighted
   neighbours spread like a line (middle over largest covariance eigenvalue below 0.25: the
   rows of a ring-sampled cloud, whose plane the fit would return) the base weights stay.
   Measured (benchmarks/normals.py; median angle to the area-weighted mesh normals / to the
   Loop limit normals, before -> after): cow 5.40 / 5.59 -> 5.18 / 5.45 deg, homer 1.98 / 2.13 ->
   1.74 / 1.90, rocker-arm 3.00 / 3.14 -> 2.77 / 2.92, cheburashka 1.23 / 1.24 -> 1.03 / 1.04,
   teapot 2.17 / 2.09 -> 1.95 / 2.05, beetle 8.75 / 8.95 -> 8.82 / 9.06, bunny 0.97 -> 0.82, Igea
   0.52 -> 0.42, spot 1.35 -> 1.07, beetle-alt 0.33 -> 0.30, beast 2.78 -> 2.49, suzanne (504
   points) 19.4 -> 19.9; normals inward or disagreeing: cow 50 -> 51, beetle 33 -> 35, teapot 39
   -> 40, suzanne 30 -> 32, spot 3 -> 1, beetle-alt 144 -> 142, others unchanged (these signs
   move through step 7, whose undetermined set follows the refitted directions; degree=4: cow
   46 -> 53 inward, median 5.58 -> 5.45 deg). On the Loop
   limit surfaces of the models sampled at their vertices (smooth, exact normals; the models'
   coarse sampling): cow 5.26 -> 4.71 deg, homer 2.13 -> 1.80, rocker-arm 2.79 -> 2.28,
   cheburashka 1.24 -> 0.90, teapot 2.21 -> 2.01, beetle 7.42 -> 7.19, bunny 1.36 -> 1.08 (the
   mesh's own area-weighted normals there: 2.85, 0.95, 1.27, 0.55, 0.49, 3.52, 0.87: the
   connectivity is worth that much). Poisson torus mean error -30 % (0.19 / 0.047 / 0.012 ->
   0.134 / 0.032 / 0.0078 deg at 2000 / 8000 / 32000 points; order 2.05), spheres unchanged
   (quadrics: the degree-2 fit is exact); random spheres with noise of 0.1 / 0.3 spacings +3 to
   +5 % mean error (4000 points: 2.35 -> 2.47, 6.85 -> 7.12 deg), none more inward; the
   synthetic thin and ring-sampled clouds unchanged. Cost: one degree-3 fit more (bunny 5.5 ->
   7.2 s, Igea about 1.3x, loaded machine). A fixed exponent 8 everywhere: noisy spheres 2.3 ->
   4.6 deg and cheburashka 45 -> 63 inward (through the base fit). Up to 12 instead of 8: the
   limit surfaces better (cow 4.57, cheburashka 0.80, bunny 0.98 deg), the models' vertices
   mixed (cow 5.24, beetle 9.17, cheburashka 0.97) and noisy spheres 3 % worse. Tried and not kept: choosing
   between the exponent-4 and -8 normals by their difference against residual-based error bars
   (noisy spheres still +40 %), sector-balanced neighbours (nearest two in each of 6 tangent
   sectors) as the base fit (cow 6.15 -> 7.84 deg) or as extra step-7 candidates (within a few
   normals either way), same-sheet refits from the 48 nearest (medians -0.2 to -0.4 deg, but
   normals more than 30 degrees off up: cow 211 -> 285, teapot 138 -> 291), excluding
   neighbours more than 45 degrees off the tangent plane from the refit (mixed, within 10 %).

6. **High degree, guarded.** With ``degree=3`` or ``4`` steps 2-5 run at degree 2
   (``k = 12``), and each particle is then refitted at the full degree with the wider
   neighbourhood, starting from its oriented degree-2 normal. The high-degree normal
   is kept where it agrees with the degree-2 one within 3 degrees (smooth parts: the
   full order, e.g. a mean error of 1.9e-4 degrees against 1.5e-2 on a 32k-point
   torus) or where its fit residual is below a quarter of the degree-2 fit's (the
   one-sided fit next to a crease); elsewhere (thin or coarse parts, where the wider
   neighbourhood reaches across) the degree-2 normal stays. Unguarded, degree 3 had a
   median error of 9.0 degrees on the cow model and 12.3 on the teapot (degree 2: 6.4
   and 2.7); guarded 6.6 and 3.5 (with the former uniform 12-point base fit). The
   normals of step 2b are kept.

7. **Consensus where the direction is undetermined.** Where the normal disagrees by
   more than 20 degrees with a plane fitted to the 8 nearest points or a quadric
   fitted to the 20 nearest (the scale test of the confidence below: thin parts a
   few points across, ring-sampled lips, coarse creases), the particle gets candidate
   directions from fits on several neighbourhoods (jets of degree 1 and 2 and PCA on
   the 8, 12, 16 and 24 nearest, and its current normal) and takes the candidate its
   neighbours agree with best: the distance-weighted mean of ``|c . R_ij n_j|`` over
   its 11 nearest, where ``R_ij n_j`` is the neighbour's normal reflected in the
   bisector plane (the reflection rule of step 3: what a circle through both points
   predicts, right across a thin tube or sheet; plain ``|c . n_j|`` did worse), plus a
   0.05 bonus for the current normal; undetermined neighbours weigh half. A few
   rounds of iterated conditional modes over all undetermined particles at once; the
   signs of these particles then follow the reflection-rule vote of their
   neighbours. Well-determined normals are untouched (smooth analytic orders and the
   cube edges unchanged; at degree 3/4 the one-sided crease fits of step 6 are kept).
   Measured against the mesh normals with the former uniform 12-point base fit and
   without steps 2b and the area rescaling of step 4 (median angle, particles more than
   30 degrees off; default before -> after): cow 6.39 -> 6.15 deg, 341 -> 238; homer 2.18 ->
   2.19, 34 -> 22; rocker-arm 3.19 -> 3.19, 20 -> 18; cheburashka 1.33 -> 1.33, 206 ->
   205; teapot 2.71 -> 2.63, 845 -> 663; beetle 11.60 -> 10.40, 235 -> 186; alligator 0,
   0; bunny 1.18 -> 1.18, 55 -> 26 (degree 4: cow 371 -> 280, teapot 897 -> 711, beetle
   256 -> 214, bunny 107 -> 82). A thin torus tube 5 points around: none more than 30
   degrees off instead of 44-59 (median 11 -> 7 deg). About 1 s on the 35k-point
   bunny (+20 %). Tried and not kept (measured on the same models): RANSAC planes
   through the particle and two neighbours as candidates (rarely right here: noise-free
   curvature dominates the inlier test), direction-balanced neighbour sets as a further
   candidate (within 1 %), a sharper agreement ``|c . R n|^p`` with p = 8 or 32 (cow and
   teapot worse), also treating particles that disagree with their neighbours'
   reflected normals (worse), refitting the chosen normals (worse), two passes (same).
   The oracle (best candidate per particle, mesh known) would leave cow 33, teapot 136
   and beetle 7 of the undetermined ones more than 30 degrees off; about half of the
   normals more than 30 degrees off pass the scale test and are not reconsidered.

**Where it stands** (``python benchmarks/normals.py``: mesh vertices as bare points
against area-weighted mesh normals; default): median angle 5.18 deg on the cow, 1.74
homer, 2.77 rocker-arm, 1.03 cheburashka, 1.95 teapot, 8.82 beetle, 0 alligator, 0.82
bunny; inward 1.76 % (cow), 0.02, 0, 0.67 % (cheburashka; 1.02 before the thickness-adapted
probes of step 4); agreeing with the mesh 98.5 % (teapot; 98.8 before the thin-part cuts of step 3 and the crossing sheets of step 4), 97.0 % (beetle). Against the
normals of the Loop limit surface at the vertices (exact; a second reference) the medians are
within 0.3 deg of these (cow 5.45, beetle 9.06): the reference is not what keeps the cow and the
beetle above 3 degrees. On the limit surfaces themselves, sampled at the models' vertices (exact
normals), the estimate is 4.71 deg on the cow and 7.19 on the beetle where the mesh's own
area-weighted normals are 2.85 and 3.52: the coarse sampling, not the reference, is the limit. What is left:
the cow's tail (a tube sampled on rings 0.5 apart, 12 points around: its fits return the
plane of the ring, 36 of the cow's 50 wrong normals) and horns, and cheburashka's concave junctions
(thin parts a few points across, creases whose mesh normals turn by 90 degrees within
a spacing); the teapot's remaining rows near the spout and handle; the beetle's coarse
CAD faces. An earlier reading, that the median angles on the coarse models measure the
reference as much as the fit, holds only in part: the area-weighted normals are first-order
(the normals with Max's weights, exact for a one-ring on a sphere, are 4.05 deg from them on
the cow, and the estimate is 3.94 deg from those against 5.18 from the area-weighted ones), but
on the exact limit surfaces above the estimate is still 4.71 deg off on the cow. The normal of
each point's umbrella of Gabriel neighbours in its tangent plane (the mesh's own construction,
first order) lies within 3.6 deg of the area-weighted normals on the cow and 0.37 on
cheburashka, while on a 300-point convex-hull sphere the mesh normals are 0.84 deg off the
exact ones and the jet fit 0.02. One-sided fits (the least-residual plane among 8 half-disks)
are farther from these averaged references (beetle 16, cow 17 deg median), so sharp-feature
fits do not help this measure.

8. **Visibility from outside** (``orient="visible"`` only). Hidden point removal (Katz,
   Tal & Basri 2007) from 48 viewpoints on a sphere of three bounding radii around the
   cloud (flip radius 10 times the farthest point; one convex hull per viewpoint): a
   normal seen from at least 3 viewpoints that makes a cosine below -0.2 with the mean
   direction towards them is flipped. On a closed surface the outward normal faces
   every viewpoint that sees its particle, whatever the local sampling, so this
   repairs what steps 3-4 cannot at thin parts: on a thin closed slab (the ellipsoid
   with semi-axes 1, 0.6 and 1 spacing, 2000 area-uniform random points) the default
   leaves 160 / 86 normals inward (seeds 0, 1; a band on one face next to the rim, whose
   directions are right but whose signs propagation carried around the rim wrongly), this
   7 / 7; semi-axis 0.5 spacing 540 / 472 -> 11 / 5, 2 spacings 7 / 9 -> 4 / 1. Not the
   default: on open or nested surfaces the inside is seen through the openings (beetle
   97.1 -> 94.3 % agreeing with the mesh, suzanne 94.1 -> 91.7 %), and on the closed test
   models it changes little (cow 50 -> 50 normals inward, cheburashka 68 -> 65, homer 1,
   rocker-arm 0 -> 1, spot 3; the open teapot 45 -> 33 disagreeing): their wrong
   normals sit where the direction itself is off (cow's tail and horns, more than 60
   degrees off for 30 of its 50) or in gaps no viewpoint sees. Noisy and random spheres
   and tori: unchanged. Time: 48 hulls, about 3 s on 10,000 points (loaded machine).

   Measured and not kept (this session; final normals of the default against the mesh
   normals): a per-particle winding-number test (``w`` at ``p -+ d n`` with ``d`` the
   smaller of the spacing and half the distance to the nearest point across, the
   particle's own dipole left out) finds 2 / 15 / 9 of the 50 / 68 / 33 wrong normals of
   cow / cheburashka / beetle and flags as many right ones; the step-4 objective evaluated
   with the final directions prefers the current signs to the mesh's on all three (it
   prefers the mesh's signs only with the mesh's directions, on cow and cheburashka), so a
   final global winding-number pass cannot reach the targets without better directions
   on thin parts; a sign from the offset to the centroid of the nearest points (away
   from the medial axis) is right at 34-40 of the cow's 50 but wrong at concave parts
   (homer 1 -> 60-150 inward); re-running steps 3-4 on the final directions, or
   down-weighting edges at low-confidence particles in the spanning tree, leaves the thin
   slab as wrong (73-125 inward) or worse. The winding number cannot resolve a slab
   thinner than the spacing: with the exact normals, the probes of the 1-spacing slab read
   ``w_in + w_out`` below 0.5 at a quarter of the particles.

9. **Voronoi poles** (``poles=True`` only; :func:`~manifold_sph.scans.poles.voronoi_poles`,
   Amenta & Bern 1999). One 3D Delaunay triangulation of the cloud gives every particle its
   pole (the farthest vertex of its Voronoi cell; at infinity on the convex hull) and its
   second pole (the farthest on the other side). The pole vector approximates the normal
   line from the empty balls touching the particle, not from its k nearest neighbours, so
   it can be right where those straddle two sheets. (a) In step 7 the pole line and a
   degree-2 fit in its frame on the 16 nearest less than 45 degrees off its tangent plane
   (not across a thin part) are two more candidates. (b) Last, the winding number of the
   oriented cloud is evaluated at both poles (far from the particle, on the medial axis,
   where the field sums many normals); where the two values differ by more than 0.3 and
   the poles lie on opposite sides (``-u_1 . u_2 > 0.2``), the pole with the smaller value
   is outside and a normal pointing away from it is flipped. Measured (median angle to the
   mesh normals / more than 30 degrees off / inward or disagreeing, default -> poles=True):
   cow 5.18 / 207 / 51 -> 5.17 / 201 / 39, teapot 1.95 / 133 / 40 -> 1.95 / 134 / 29, beetle
   8.82 / 154 / 35 -> 8.82 / 152 / 32, cheburashka 1.03 / 184 / 45 unchanged, homer 21 -> 20
   more than 30 degrees off (1 inward), rocker-arm 12 -> 11, alligator and woody unchanged,
   spot 5 -> 7 off (1 inward), suzanne 19.9 / 177 / 32 -> 20.5 / 182 / 33, beetle-alt
   142 -> 74 disagreeing (the sign check: its thin sheets); alone, (b) gives cow 43, teapot
   32, beetle 34, cheburashka 44, suzanne 33, beetle-alt 73 and (a) cow 46, beetle 33, teapot
   38, cheburashka 46. Thin closed slabs (flat ellipsoids, seeds 0, 1; inward of 2000): 2
   spacings thick 160 / 86 -> 152 / 79, 4 spacings 7 / 8 -> 3 / 5, 1 spacing 537 / 473 ->
   530 / 469; thin and meridian tori slightly better (mean error 8.4 -> 8.1 deg, 37 / 2 ->
   37 / 0 more than 30 degrees off); analytic spheres and tori unchanged. With ``degree=4``
   (inward or disagreeing) cow 53 -> 41, cheburashka 46 -> 45, beetle 33 -> 32, teapot 43 ->
   36; with ``orient="visible"`` cow 51 -> 42, cheburashka 43 -> 42, teapot 34 -> 27, beetle
   66 -> 64. The bunny (unchanged), beast (32,311 points; 91.11 -> 91.27 % agreeing) and
   the well-sampled models barely change. On area-uniform random samples of the same meshes
   (``python benchmarks/normals.py --random --poles``: as many points as vertices, seeds 0, 1,
   against the normals of the faces sampled) the gain is smaller and mixed: inward or
   disagreeing cow 74 / 59 -> 67 / 57, homer 6 / 71 -> 8 / 63, rocker-arm 1 / 0 unchanged,
   cheburashka 42 / 48 -> 37 / 46, teapot 70 / 112 -> 66 / 107, beetle 24 / 15 -> 22 / 16,
   alligator 0 (522 -> 490 in all); with other sample sizes (seeds 0, 1) cow 45 / 79 -> 45 / 77
   of 3000, cheburashka 37 / 67 -> 40 / 69 of 6000, teapot 53 / 84 -> 54 / 83 of 3000, homer 7 /
   54 -> 8 / 54 of 6000, spot 0 / 0 of 3000. Not the default: the triangulation and the sign check cost
   about 10 s more on the 35,000-point bunny (benchmark, loaded machine: 6.5 -> 16.4 s; the
   qhull triangulation alone 4.5-7 s, 28 s on Igea's 134,000 points), and noisy clouds get
   worse (the poles of a noisy layer are random): uniformly random spheres of 4000 points with noise of 0.1 / 0.3 / 0.5
   spacings, inward 0 / 5 / 84 -> 1 / 9 / 90 (seed=3), 0 / 4 / 106 -> 0 / 14 / 106 (seed=4).
   The thresholds are sensitive: a jump of 0.2 flips the teapot's rows (40 -> 69), 0.4
   gives cow 47; without the opposite-sides condition noisy spheres flip many more (12 of
   4000 at 0.3 spacings; the noisy flips had ``-u_1 . u_2`` below 0.17 there, the cow's
   right ones above 0.23). Measured and not kept: the raw pole line as the normal where it
   disagrees with the fit (on these coarse models the poles are worse: median 12.3 deg on
   the cow, 5.7 on cheburashka, and where pole and fit disagree by more than 30 degrees
   neither is right more often, whatever the pole radius over the spacing or the angle
   between the two poles); the rim normal (the pole away from the neighbours' centroid at
   particles on the edge of their neighbourhood: cheburashka 45 -> 76-157 inward);
   particles whose line disagrees with the pole by more than 30 / 45 degrees added to the
   undetermined set of step 7 (teapot 40 -> 48, suzanne 32 -> 36); a prior for the pole
   candidate (0.05: teapot 40 -> 43, beetle 154 -> 165 off); repeating (b) (cow 43 -> 45);
   requiring clean winding numbers at the poles (near 0 and 1: no flips left, the poles of
   thin parts sit about a spacing from the surface); the poles as extra probes of step 4
   (inner pole 1, outer 0 in the patch objective, weight 0.5 / 1 / 3 of the probes: cow 39
   -> 37 / 42 / 42, teapot 29 -> 31 / 34 / 34, beetle 32 -> 32 / 30 / 30, cheburashka 45);
   a power-crust-like labelling of the poles (Amenta, Choi & Kolluri 2001: the two poles of a
   particle opposite, the poles of neighbours whose balls overlap deeply alike, the hull
   poles outside; spanning tree of the overlap depth): right at 96 % (cow) to 99.8 % (homer)
   of the particles, but as a sign check it breaks 3-10 times more normals than it repairs
   (cow 21 / 84, cheburashka 10 / 86, teapot 14 / 219; among particles with a confidence
   below 0.5 still 21 / 65, 9 / 64, 14 / 119). Cheburashka's wrong normals are mostly
   particles whose two poles both read ``w`` near 1 (or both near 0: cracks and junctions), so
   the poles do not tell their side.

``method="pca"`` stops after step 1 (with the given ``k``, default 16) and orients.

The per-particle **confidence** is the product of the shape term
``1 - lambda_0 / lambda_1`` of the PCA (1 on a clean flat neighbourhood, near 0 where
it is isotropic: noise, outliers, corners; or collinear) and an orientation term:
how clearly the winding number jumps from 1 to 0 across the particle
(``clip(w_in - w_out, 0, 1)`` at the particle, or at its nearest probe), low where
the orientation is in doubt; and a scale term: the agreement of the normal with a
plane fitted to the 8 nearest points and a quadric fitted to the 20 nearest
(1 within 10 degrees of both, 0 beyond 30, linear in the cosine between). A normal
that changes with the neighbourhood size is not determined by the points: thin parts
sampled a few points across, ring-sampled lips, coarse creases. A normal chosen by the
consensus of step 7 keeps the scale term of the one it replaced (the points did not
determine it). Measured against the mesh normals of the test models (share of the
normals more than 30 degrees off or pointing the wrong way that get a confidence below
0.5, and of the others): cow 0.89 and 0.21, homer 0.91 and 0.05, rocker-arm 0.89 and
0.03, cheburashka 0.83 and 0.04, teapot 0.61 and 0.21, beetle 0.67 and 0.22, alligator
(none doubtful) 0.0, bunny 0.85 and 0.01 (before step 7: 0.92 and 0.18 on the cow, 0.69
and 0.15 on the teapot; step 7 repairs flagged normals only, so the same doubtful ones
are missed, 28 on the cow and 269 on the teapot, out of fewer; without the scale term
0.31, 0.47, 0.0, 0.50, 0.08 and 0.04 of the doubtful normals were flagged). With the
weighted base fit and steps 2b and 4 as now: cow 0.86 and 0.21 of 218 doubtful, teapot
0.53 and 0.24 of 152 (its repaired rows disagree with the 8- and 20-point fits by construction; a normal
of step 2b with no point steeply on both sides of its plane keeps a scale term of 1).

Last, a **thickness term** ``min(1, t / s)``: ``t`` the height above or below the tangent
plane of the nearest of the 16 nearest points that lies steeply across it (more than 45
degrees off the plane, and higher than 4 times the cloud's noise level: the median
relative residual of the jet fits times the fit radius), ``s`` the median distance to the
6 nearest. It is below 1 on the two sides of a part or a gap thinner than the spacing,
where the winding number cannot tell inside from outside and propagation jumps between
the sides (the teapot's lip and rows, the beetle's thin sheets, cheburashka's cracks).
Share of the doubtful normals (more than 30 degrees off or inward) with a confidence
below 0.5, and of the others, without -> with it: cow 0.86 / 0.21 -> 0.88 / 0.22, teapot
0.53 / 0.24 -> 0.88 / 0.24, beetle 0.57 / 0.21 -> 0.61 / 0.22, cheburashka 0.80 / 0.04 ->
0.85 / 0.04, suzanne (504 points) 0.71 / 0.41 -> 0.74 / 0.45; homer, rocker-arm, spot and
the bunny unchanged. A Poisson sphere with noise of 0.3 spacings (every normal within 30
degrees) 0.9 -> 1.4 % below 0.5 (without the noise guard 11.5 %, where the flags carry no
information: mean error 8.4 deg flagged, 7.4 not; with a guard of 2 noise levels 8 %, of 3
4 %, where the beetle keeps 0.64-0.68), with 0.5 spacings 36.9 -> 38.0 %; smooth tori and
spheres unchanged. Tried instead and not kept: the median height of the particle's other
neighbours as the noise level (the teapot's lip lost its flags: 0.56), and two points
across on one side (the thin part's signal is the single point straight across).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .. import _jit as _jitmod
from .._validation import as_points, check_int
from ..threads import get_num_threads, run_chunks

__all__ = [
    "estimate_normals",
    "pca_normals",
    "jet_normals",
    "orient_normals",
    "ORIENTATIONS",
    "METHODS",
    "DEFAULT_K",
    "DEFAULT_JET_K",
]

#: Orientation modes of :func:`estimate_normals` (a viewpoint (3,) is also accepted).
ORIENTATIONS = ("outward", "visible", "consistent", "none")

#: Normal estimators of :func:`estimate_normals`.
METHODS = ("jet", "pca")

#: Default number of nearest neighbours (itself included) of ``method="pca"``.
DEFAULT_K = 16

#: Default neighbours (itself included) of the jet fit, by degree: about twice the
#: number of coefficients (chosen by measurement on the test models and on spheres/tori).
DEFAULT_JET_K = {1: 10, 2: 16, 3: 20, 4: 30}

_PCA_K = 10  # neighbours of the first PCA normal (smaller is better on coarse models, measured)
_REFIT_DOT = 0.7  # neighbours kept by the refit: n_i . n_j above this (0.8 and 3 iterations: better
_REFIT_ITERATIONS = 2  # on cube edges, but worse on tori, noise and the cow; measured)
_ORIENT_K = 10  # neighbours of the orientation graph
_TRUST = 0.9  # spanning-tree edges below this confidence may separate patches
_MAX_PATCHES = 400
_MIN_PATCH = 8
_MAX_PROBES = 6000  # particles probed by the winding number (all of them up to this many)
_PROBE_OFFSET = 1.0  # probe distance over the local spacing (0.5: noisy clouds flip, measured)
_ROUNDS = 3
_BRIDGE_K = 30  # nearest neighbours searched for an edge to another k-NN component
_BRIDGE_MAX_SIZE = 4096  # components up to this size with no such neighbour are searched further
_BRIDGE_MAX_LONELY = 256  # at most this many of them (isolated clumps of a scan are few)
_SCALE_K = (8, 20)  # neighbourhoods of the scale term of the confidence (a plane, a quadric)
_SCALE_COS = (np.cos(np.radians(30.0)), np.cos(np.radians(10.0)))  # its 0 and 1
_THIN_K = 16  # thickness term of the confidence: the nearest point steeply across among these
_THIN_NOISE = 4.0  # ... and higher than this many times the cloud's noise level (2: 8 % of a noisy sphere flagged)
_GUARD_DEGREES = 3.0  # a degree-3/4 normal within this angle of the degree-2 one is kept, or
_GUARD_RESIDUAL = 0.25  # one whose fit residual is below this fraction of the degree-2 fit's (measured)
_CONSENSUS_DEGREES = 20.0  # step 7 where the scale agreement is below cos of this
_CONSENSUS_CANDIDATES = ((8, 1), (12, 2), (16, 2), (24, 2), (16, 1), (24, 1), (8, 0), (16, 0), (24, 0))  # (k, degree; 0: PCA)
_CONSENSUS_K = 12  # neighbours (itself included) whose reflected normals vote
_CONSENSUS_PRIOR = 0.05  # bonus of the current normal (of a mean |cos| in [0, 1])
_CONSENSUS_ROUNDS = 5
_CALIBRATE = True
_POLE_FITS = ((16, 2),)  # poles=True: step-7 candidates fitted in the pole frame (k, degree), besides the pole
_POLE_JUMP = 0.3  # poles=True, step 9: the winding numbers at the two poles differ by more than this
_POLE_ANTI = 0.2  # ... and the two poles lie on opposite sides: -u1 . u2 above this (noisy spheres: below 0.17)
_THICK_PROBE = 0.5  # step 4: probes at most this fraction of the height of the point across a thin part,
_THICK_FLOOR = 0.3  # at least this fraction of the usual offset (suzanne 30 -> 45 inward without it)
_THICK_PAR = 0.9  # across: a point steeply off the tangent plane with |n_i . n_j| above this (0: suzanne 42)
_THICK_NOISE = 12.0  # and higher than this many noise levels (8: noisy random spheres flipped more, measured)
_CUT_THIN = 0.5  # step 3: tree edges where the reflection and parallel rules disagree (|n_i . n_j| above this) are doubtful
_SHEETS = True  # step 4: closed sheets (crossing surfaces cut apart) are judged by their own field
_SHEET_DOT = 0.8  # sheet edges: |n_i . n_j| above this
_SHEET_TAN = 0.6  # ... and each end within atan(this) of the other's tangent plane
_SHEET_JUNCTION = 0.8  # a junction: two of its sheet neighbours with |n_j . n_k| below this,
_SHEET_SHAPE = 0.42  # unless one shape operator explains their normals to this relative residual
_SHEET_SUPPORT = 2  # sheet edges lie in at least this many triangles of sheet edges
_SHEET_PRUNE = 2  # (pruned this many times)
_SHEET_GROW = 30  # rings over which left-out particles join a sheet (over sheet edges)
_SHEET_MIN = 100  # sheets have at least this many particles
_SHEET_FRACTION = 0.005  # ... and this fraction of the cloud
_SHEET_CLOSED = 0.6  # closed: |mean(w_in + w_out)| of a sheet's own field at least this
_SHEET_NESTED = 0.95  # ... unless this share of their probes lies inside the other sheets' field
_SHEET_SEALED = 0.8  # (wholly inside and sealed: |mean(w_in + w_out)| at least this; a sheet inside but open
#  lost its outside part where it crosses another surface)
_SHEET_CROSS = 0.1  # applied where a closed sheet has at least this share inside another (0.005: cheburashka worse)
_SHEET_MAX_JUNCTION = 0.25  # and at most this share of the particles are junctions
_FLAG_S = 0.5  # probes with w_in + w_out below this (both outside: a flipped thin part) start patches (was -0.5)
_FLAG_S_HIGH = 1.5  # ... or above this (both inside: a flipped patch in a crevice or narrow gap; None: off),
_HIGH_MIN = 12  # (regions of fewer particles, connected over the spanning tree, are not flagged)
_FLAG_S_EXPLAIN = 0.5  # patches of their own, flipped only where that leaves at most this part of their excess S - 1
_ROW_K = 32  # step 2b: neighbours searched for points steeply above and below the fitted plane
_ROW_STEEP = 2  # at least this many on each side
_ROW_TAN = 1.0  # steep: height above the plane over the distance along it (1: 45 degrees)
_ROW_LINE = 0.02  # particles whose 10 nearest have a middle PCA eigenvalue below this fraction of the largest
_ROW_K_LINE = 96  # (on a line) are tested with this many
_JET_WEIGHT = 4.0  # base jet fits weigh neighbour j by exp(-a (r_j / r_k)^2), r_k the farthest (measured)
_SHARP_WEIGHT = 8.0  # step 5 refit: up to this exponent where the fit residual is structured (bias, not noise):
_SHARP_RHO = (0.55, 0.7)  # where the degree-3 / degree-2 residual ratio (median over the neighbours) is below
# the first (the full exponent) to above the second (the base one; pure noise reads about 0.8); measured
_SHARP_LINE = 0.25  # ... unless the sharply weighted neighbours spread like a line (middle over largest
# eigenvalue of their covariance below this: rows of a ring-sampled cloud; 0.12-0.15 there, models 0.3-0.8)
_VIS_VIEWS = 48  # orient="visible": viewpoints (Fibonacci sphere, 3 bounding radii out)
_VIS_GAMMA = 1.0  # hidden-point-removal flip radius 10**gamma times the farthest point (2: beetle worse, measured)
_VIS_COS = 0.2  # a normal is flipped where it makes less than -this with the mean direction to its viewpoints
_VIS_MIN_VIEWS = 3  # ... seen from at least this many


def _distance_weights(pts, neighbors, alpha=None):
    """Gaussian weights ``exp(-alpha (r_j / r_max)^2)`` of the neighbours of every row (scale-free).

    ``alpha``: a number, or one per row (shape (N,))."""
    alpha = _JET_WEIGHT if alpha is None else alpha
    r2 = np.einsum("nki,nki->nk", pts[neighbors] - pts[neighbors[:, :1]], pts[neighbors] - pts[neighbors[:, :1]])
    rmax = r2.max(axis=1, keepdims=True)
    return np.exp(-np.reshape(alpha, (-1, 1)) * r2 / np.where(rmax > 0, rmax, 1.0))


def _sharpened_weights(pts, neighbors, frame, weights, residual2):
    """Weights of the step-5 refit: sharper where the base fit's residual is bias, not noise.

    ``residual2``: the relative residual of the degree-2 fit with ``weights`` in the frames of
    ``frame``; the same neighbours are fitted at degree 3 in the same frames. Where the residual
    ratio ``rho = res3 / res2`` (median over the row's neighbours) is small, the residual is
    structure that a higher degree explains (a coarsely sampled, strongly curved part, where the
    neighbourhood is too wide: bias), and the Gaussian exponent rises from ``_JET_WEIGHT``
    (``rho`` above ``_SHARP_RHO[1]``) to ``_SHARP_WEIGHT`` (below ``_SHARP_RHO[0]``), linearly
    between. Noise leaves ``rho`` near 0.8 (measured: 0.80-0.82 median, 0.68-0.76 at the 10th
    percentile, on spheres with noise of 0.01-0.3 spacings), so noisy clouds keep the wide
    weights. Where the sharply weighted neighbours spread like a line (``_SHARP_LINE``: the
    rows of a ring- or scan-line-sampled cloud) the base weights stay. Scale-free, so the
    order on smooth surfaces is kept (module notes, step 5).
    """
    res3 = np.zeros(pts.shape[0])
    _jet_fit(pts, neighbors, frame, 3, weights=weights, residual=res3)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(residual2 > 0, res3 / residual2, 1.0)
    rho = np.median(rho[neighbors], axis=1)
    lo, hi = _SHARP_RHO
    alpha = _JET_WEIGHT + (_SHARP_WEIGHT - _JET_WEIGHT) * np.clip((hi - rho) / (hi - lo), 0.0, 1.0)
    sharp = _distance_weights(pts, neighbors, alpha)
    # rows (scan lines, meridian circles): the sharper weights fall on the particle's own row,
    # whose plane the fit would return; keep the base weights where their spread is line-like
    L = pts[neighbors] - pts[:, None, :]
    L -= np.einsum("nk,nki->ni", sharp, L)[:, None, :] / sharp.sum(axis=1)[:, None, None]
    ev = np.linalg.eigvalsh(np.einsum("nk,nki,nkj->nij", sharp, L, L))
    with np.errstate(divide="ignore", invalid="ignore"):
        line = ~(ev[:, 1] >= _SHARP_LINE * ev[:, 2])
    return np.where(line[:, None], weights, sharp)


def _knn(points: np.ndarray, k: int, tree: cKDTree | None = None):
    tree = cKDTree(points) if tree is None else tree
    dist, idx = tree.query(points, k=k, workers=get_num_threads())
    return dist, idx


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _covariance(pts: np.ndarray, neighbors: np.ndarray):
    nbr = pts[neighbors]  # (N, k, 3)
    # centre on the particle's own mean; subtract the particle first for conditioning
    local = nbr - pts[:, None, :]
    local -= local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local) / neighbors.shape[1]
    return np.linalg.eigh(cov)  # ascending eigenvalues


def _scale_confidence(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, before=None) -> np.ndarray:
    """1 where ``normals`` agree within 10 degrees with fits on smaller and larger neighbourhoods, 0 beyond 30.

    ``before``: the agreement before the consensus of step 7 (a normal chosen there stays
    as doubtful as the one it replaced: the points did not determine it)."""
    if before is None:
        agree = _scale_agreement(pts, neighbors, normals)
    else:  # only the particles step 7 reconsidered can have changed: refit those alone
        rows = np.flatnonzero(before < np.cos(np.radians(_CONSENSUS_DEGREES)))
        agree = before.copy()
        agree[rows] = np.minimum(before[rows], _scale_agreement(pts, neighbors, normals, rows))
    lo, hi = _SCALE_COS
    return np.clip((agree - lo) / (hi - lo), 0.0, 1.0)


def _thin_confidence(pts, neighbors, distances, normals, noise=0.0):
    """``min(1, t / s)``: ``t`` the height above or below the tangent plane of the nearest point
    lying steeply across it (more than 45 degrees off the plane, and higher than
    ``_THIN_NOISE * noise`` times the distance to the farthest neighbour, ``noise`` the cloud's
    median relative jet-fit residual), ``s`` the local spacing (median distance to the 6
    nearest). Below 1 on the two sides of a part or a gap thinner than the spacing, which
    neither the winding number nor propagation resolves (module notes)."""
    L = pts[neighbors[:, 1:]] - pts[:, None, :]
    zs = np.einsum("nkj,nj->nk", L, normals)
    z = np.abs(zs)
    lateral2 = np.maximum(np.einsum("nkj,nkj->nk", L, L) - z * z, 0.0)
    steep = z * z > lateral2
    s = np.median(distances[:, 1 : min(7, distances.shape[1])], axis=1)
    # noise guard: only points across by more than _THIN_NOISE times the cloud's noise level
    # (``noise``: the median relative residual of the jet fits, times the fit radius)
    t = np.where(steep & (z > _THIN_NOISE * noise * distances[:, -1:]), z, np.inf).min(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0, np.clip(t / np.where(s > 0, s, 1.0), 0.0, 1.0), 1.0)


def _shape_confidence(w: np.ndarray) -> np.ndarray:
    w = np.maximum(w, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(w[:, 1] > 0, w[:, 0] / w[:, 1], 1.0)
    return np.clip(1.0 - ratio, 0.0, 1.0)


def pca_normals(points: ArrayLike, k: int = DEFAULT_K, *, neighbors: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented PCA normals and their confidence.

    Parameters
    ----------
    points : array_like, shape (N, 3)
    k : int
        Neighbours per particle, itself included (at least 3, below N).
    neighbors : ndarray of int, shape (N, k), optional
        Precomputed neighbour indices (overrides ``k``).

    Returns
    -------
    normals : ndarray, shape (N, 3)
        Unit normals with the sign convention of ``numpy.linalg.eigh`` (arbitrary).
    confidence : ndarray, shape (N,)
        ``1 - lambda_0 / lambda_1`` in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = np.c_[rng.uniform(size=(200, 2)), np.zeros(200)]     # the plane z = 0
    >>> n, c = pca_normals(p, k=10)
    >>> float(np.abs(n[:, 2]).min().round(6)), float(c.min().round(6))
    (1.0, 1.0)
    """
    pts = as_points("points", points)
    if neighbors is None:
        k = check_int("k", k, minimum=3)
        if k > pts.shape[0]:
            raise ValueError(f"k must be at most the number of points {pts.shape[0]}, got {k}")
        _, neighbors = _knn(pts, k)
    w, v = _covariance(pts, neighbors)
    return v[:, :, 0], _shape_confidence(w)


# ----------------------------------------------------------------------------- jet fits
def _monomials(degree: int) -> list:
    return [(a, d - a) for d in range(degree + 1) for a in range(d, -1, -1)]


def _n_coefficients(degree: int) -> int:
    return (degree + 1) * (degree + 2) // 2


def _tangents(n: np.ndarray):
    a = np.where(np.abs(n[:, :1]) < 0.6, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = _unit(np.cross(n, a))
    return t1, np.cross(n, t1)


def _jet_fit(pts: np.ndarray, neighbors: np.ndarray, frame: np.ndarray, degree, weights=None, residual=None,
             centers: np.ndarray | None = None) -> np.ndarray:
    """Normals of degree-``degree`` height-function fits in the tangent frames of ``frame``.

    ``degree`` is an int or a per-particle int array (0 keeps the frame normal);
    ``weights`` (N, k) zero out neighbours. Rows are batched by degree. Row ``r`` is
    centred on ``pts[r]``, or on ``centers[r]`` when given (fits of a subset of rows).
    """
    centers = pts if centers is None else centers
    N = frame.shape[0]
    degs = np.broadcast_to(np.asarray(degree, dtype=np.int64), (N,))
    out = frame.copy()
    t1, t2 = _tangents(frame)
    for d in np.unique(degs):
        if d <= 0:
            continue
        rows = np.flatnonzero(degs == d)
        for lo in range(0, rows.size, 20000):  # bound the (rows, k, m) temporaries
            r = rows[lo : lo + 20000]
            local = pts[neighbors[r]] - centers[r, None, :]
            x = np.einsum("nki,ni->nk", local, t1[r])
            y = np.einsum("nki,ni->nk", local, t2[r])
            z = np.einsum("nki,ni->nk", local, frame[r])
            s = np.sqrt((x * x + y * y).max(axis=1, keepdims=True))
            s = np.where(s > 0, s, 1.0)
            u, v = x / s, y / s
            mons = _monomials(int(d))
            V = np.stack([u**a * v**b for a, b in mons], axis=2)
            w = np.ones_like(u) if weights is None else weights[r]
            A = np.einsum("nkp,nk,nkq->npq", V, w, V)
            rhs = np.einsum("nkp,nk,nk->np", V, w, z)
            tr = np.trace(A, axis1=1, axis2=2)
            A += (1e-10 * tr + 1e-300)[:, None, None] * np.eye(len(mons))
            c = np.linalg.solve(A, rhs[..., None])[..., 0]
            gx = c[:, mons.index((1, 0))] / s[:, 0]
            gy = c[:, mons.index((0, 1))] / s[:, 0]
            n = frame[r] - gx[:, None] * t1[r] - gy[:, None] * t2[r]
            ok = np.all(np.isfinite(n), axis=1)
            out[r[ok]] = _unit(n[ok])
            if residual is not None:
                res = z - np.einsum("nkp,np->nk", V, c)
                residual[r] = np.sqrt((w * res * res).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)) / s[:, 0]
    return out


def _refit(pts, neighbors, normals, degree, iterations=None, threshold=None, residual=None, weights=None):
    """Refit with only the neighbours whose oriented normal agrees (``n_i . n_j > threshold``)."""
    iterations = _REFIT_ITERATIONS if iterations is None else iterations
    threshold = _REFIT_DOT if threshold is None else threshold
    need = _n_coefficients(degree) + 2
    n = normals
    for _ in range(iterations):
        dots = np.einsum("nkj,nj->nk", n[neighbors], n)
        w = (dots > threshold).astype(np.float64)
        w[:, 0] = 1.0  # the particle itself (first neighbour)
        count = w.sum(axis=1)
        deg = np.where(count >= need, degree, np.where(count >= 5, 1, 0))
        n = _jet_fit(pts, neighbors, n, deg, w if weights is None else w * weights, residual=residual)
    return n


def _high_order(pts, neighbors, base, base_residual, degree, refine):
    """Degree-``degree`` fits started from the oriented ``base`` (degree-2) normals, guarded.

    The high-degree normal replaces the base one where the two agree within
    ``_GUARD_DEGREES`` (smooth, well-resolved parts: the error drops from ``O(h^2)``
    to ``O(h^degree)``) or where its fit residual is below ``_GUARD_RESIDUAL`` times the
    base fit's (one face of a crease found by the wider neighbourhood). Elsewhere, on
    thin or coarsely sampled parts where the wider neighbourhood of a high-degree fit
    reaches across, the base normal is kept (module notes, step 6).
    """
    res = np.zeros(pts.shape[0])
    if refine:
        hi = _refit(pts, neighbors, base, degree, residual=res)
    else:
        hi = _jet_fit(pts, neighbors, base, degree, residual=res)
    dot = np.einsum("ij,ij->i", hi, base)
    close = np.abs(dot) > np.cos(np.radians(_GUARD_DEGREES))
    one_sided = ~close & (res < _GUARD_RESIDUAL * base_residual)
    return np.where((close | one_sided)[:, None], hi, base), one_sided


def _scale_agreement(pts, neighbors, normals, rows=None):
    """``min |n . n'|`` over a plane fitted to the 8 nearest and a quadric to the 20 nearest
    (of every particle, or of ``rows`` only)."""
    rows = np.arange(pts.shape[0]) if rows is None else rows
    agree = np.ones(rows.size)
    for k, degree in zip(_SCALE_K, (1, 2)):
        k = min(k, neighbors.shape[1])
        if k < _n_coefficients(degree) + 2:
            continue
        other = _jet_fit(pts, neighbors[rows, :k], normals[rows], degree, centers=pts[rows])
        agree = np.minimum(agree, np.abs(np.einsum("ij,ij->i", other, normals[rows])))
    return agree


def _reflected(pts, rows, nbrs, m):
    """Normals ``m`` (R, K, 3) at ``pts[nbrs]`` reflected in the bisector planes of ``p_i p_j``:
    the normals predicted at ``pts[rows]`` (the reflection rule of step 3)."""
    e = _unit(pts[nbrs] - pts[rows][:, None, :])
    return m - 2.0 * np.einsum("rkj,rkj->rk", m, e)[..., None] * e


def _consensus(pts, neighbors, normals, fixed=None, pole=None):
    """Undetermined directions chosen among candidates by agreement with the neighbours (step 7).

    Where the normal disagrees with the plane of the 8 nearest or the quadric of the
    20 nearest by more than ``_CONSENSUS_DEGREES``, candidate directions come from jet
    fits and PCA on several neighbourhoods (``_CONSENSUS_CANDIDATES``) and the current
    normal; each such particle takes the candidate that maximises the distance-weighted
    sum of ``|c . R_ij n_j|`` over its neighbours (``R_ij n_j``: the neighbour's normal
    reflected in the bisector plane, the normal a circle through both points predicts
    at ``p_i``; right across a thin tube or sheet), plus ``_CONSENSUS_PRIOR`` for the
    current normal. A few rounds of iterated conditional modes, all undetermined
    particles at once; the signs then follow the reflection-rule vote of the neighbours.
    Returns the normals and the scale agreement before (None when not run).
    """
    if neighbors.shape[1] < max(k for k, _ in _CONSENSUS_CANDIDATES):
        return normals, None
    agree = _scale_agreement(pts, neighbors, normals)
    undetermined = agree < np.cos(np.radians(_CONSENSUS_DEGREES))
    if fixed is not None:
        undetermined &= ~fixed
    rows = np.flatnonzero(undetermined)
    if rows.size == 0:
        return normals, agree
    base = normals[rows]
    cands = []
    for k, degree in _CONSENSUS_CANDIDATES:
        if degree == 0:
            cands.append(_pca_rows(pts, neighbors[rows, :k]))
        else:
            cands.append(_jet_fit(pts, neighbors[rows, :k], base, degree, centers=pts[rows]))
    if pole is not None:  # poles=True: the Voronoi pole line, and fits in its frame (module notes, step 9)
        e = _unit(pole[rows])
        e = np.where(np.einsum("ij,ij->i", e, e)[:, None] > 0.5, e, base)  # no pole (a duplicate): its own normal
        cands.append(e)
        for kp, dp in _POLE_FITS:
            kp = min(kp, neighbors.shape[1])
            nbp = neighbors[rows, :kp]
            L = pts[nbp] - pts[rows][:, None, :]
            z = np.einsum("rkj,rj->rk", L, e)
            # only the neighbours less than 45 degrees off the pole's tangent plane (not across a thin part)
            wp = (2.0 * z * z <= np.einsum("rkj,rkj->rk", L, L)).astype(np.float64)
            few = wp.sum(axis=1) < _n_coefficients(dp) + 2
            cands.append(np.where(few[:, None], e, _jet_fit(pts, nbp, e, dp, weights=wp, centers=pts[rows])))
    cands.append(base)
    C = np.stack(cands, axis=1)  # (R, c, 3)
    prior = np.zeros(C.shape[:2])
    prior[:, -1] = _CONSENSUS_PRIOR
    nb = neighbors[rows, 1:_CONSENSUS_K]
    d = np.linalg.norm(pts[nb] - pts[rows][:, None, :], axis=2)
    dmax = d.max(axis=1, keepdims=True)
    w = np.where(undetermined[nb], 0.5, 1.0) * np.exp(-(d / np.where(dmax > 0, dmax, 1.0)) ** 2)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    n = normals.copy()
    choice = np.full(rows.size, -1)
    for _ in range(_CONSENSUS_ROUNDS):
        pred = _reflected(pts, rows, nb, n[nb])
        score = np.einsum("rck,rk->rc", np.abs(np.einsum("rcj,rkj->rck", C, pred)), w) + prior
        new = score.argmax(axis=1)
        if np.array_equal(new, choice):
            break
        choice = new
        c = C[np.arange(rows.size), choice]
        n[rows] = c * np.where(np.einsum("ij,ij->i", c, base) < 0, -1.0, 1.0)[:, None]
    # signs: the reflection-rule vote of the neighbours
    vote = np.einsum("rkj,rj->r", _reflected(pts, rows, nb, n[nb]) * w[..., None], n[rows])
    n[rows] *= np.where(vote < 0, -1.0, 1.0)[:, None]
    return n, agree


def _pole_signs(pts, nrm, distances, poles):
    """Signs from the winding number at the two Voronoi poles of every particle (``poles=True``, step 9).

    ``poles``: ``(pole, radius, second)`` of :func:`~manifold_sph.scans.poles.voronoi_poles`. The
    winding number ``w`` of the oriented cloud is evaluated at both poles (0 at a pole at infinity);
    where the two differ by more than ``_POLE_JUMP`` and the poles lie on opposite sides of the
    particle (``-u_1 . u_2 > _POLE_ANTI``), the pole with the smaller ``w`` is outside, and a normal
    pointing away from it (``n . u_out < 0``) is flipped. Returns the normals and the flipped mask.
    """
    N = pts.shape[0]
    pole, radius, second = poles
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    hull = ~np.isfinite(radius)
    has2 = np.einsum("ij,ij->i", second, second) > 0
    q = np.vstack([pts + np.where(hull[:, None], 0.0, pole), pts + second])
    W = _winding_numbers(q, pts, nrm, area, 0.2 * np.sqrt(area), np.zeros(N, dtype=np.int64), 1)[:, 0]
    w1, w2 = np.where(hull, 0.0, W[:N]), W[N:]
    out = np.where((w1 < w2)[:, None], pole, second)
    anti = -np.einsum("ij,ij->i", _unit(pole), _unit(second))
    flip = has2 & (np.abs(w1 - w2) > _POLE_JUMP) & (anti > _POLE_ANTI) & (np.einsum("ij,ij->i", out, nrm) < 0)
    return np.where(flip[:, None], -nrm, nrm), flip


def _steep(pts, neighbors, normals, rows=None):
    """Counts of the neighbours more than 45 degrees above and below the tangent plane of ``normals``.

    ``neighbors``: (R, K) neighbour lists of ``rows`` (all particles when None)."""
    rows = np.arange(pts.shape[0]) if rows is None else rows
    L = pts[neighbors] - pts[rows][:, None, :]
    z = np.einsum("nki,ni->nk", L, normals[rows])
    rho2 = np.einsum("nki,nki->nk", L, L) - z * z
    steep = z * z > _ROW_TAN**2 * np.maximum(rho2, 0.0)
    return (steep & (z > 0)).sum(axis=1), (steep & (z < 0)).sum(axis=1), L, z, steep


def _rows_across(pts, neighbors, normals, rows=None):
    """Step 2b: normals of particles whose tangent plane cuts through the cloud (module notes).

    A fitted plane through a particle normally has the nearby points of the surface close
    to it (heights of order ``kappa r^2``); points far above AND below it (more than 45
    degrees, at least ``_ROW_STEEP`` on each side among the neighbours) mean the fit saw one
    row of a cloud sampled along planar curves (the meridian rows of a surface of
    revolution, scan lines) and returned the plane of the row. The candidate normal is
    perpendicular to the row (the line to the nearest neighbour) and to the direction to
    the nearest steep point on each side (the adjacent rows); it replaces the fit where it
    at least halves the smaller of the two steep counts. ``neighbors``: (R, K) lists of
    ``rows`` (all particles when None). Returns the normals and the mask of replaced ones.
    """
    N = pts.shape[0]
    rows = np.arange(N) if rows is None else rows
    up, down, L, z, steep = _steep(pts, neighbors, normals, rows)
    sel = np.flatnonzero((up >= _ROW_STEEP) & (down >= _ROW_STEEP))
    changed = np.zeros(N, dtype=bool)
    if sel.size == 0:
        return normals, changed
    L, z, steep, nb = L[sel], z[sel], steep[sel], neighbors[sel]
    rows = rows[sel]
    r2 = np.einsum("nki,nki->nk", L, L)
    r = np.arange(rows.size)
    e_up = L[r, np.where(steep & (z > 0), r2, np.inf).argmin(axis=1)]
    e_dn = L[r, np.where(steep & (z < 0), r2, np.inf).argmin(axis=1)]
    t = L[r, np.where(r2 > 0, r2, np.inf).argmin(axis=1)]  # the nearest neighbour: along the row
    c1, c2 = _unit(np.cross(t, e_up)), _unit(np.cross(t, e_dn))
    cand = _unit(c1 + c2 * np.where(np.einsum("ij,ij->i", c1, c2) < 0, -1.0, 1.0)[:, None])
    ok = np.all(np.isfinite(cand), axis=1) & (np.linalg.norm(cand, axis=1) > 0.5)
    trial = normals.copy()
    trial[rows[ok]] = cand[ok]
    cu, cd, *_ = _steep(pts, nb, trial, rows)
    before = np.minimum(up[sel], down[sel])
    accept = ok & (np.minimum(cu, cd) <= before // 2)
    out = normals.copy()
    out[rows[accept]] = cand[accept]
    changed[rows[accept]] = True
    return out, changed


def _rows_step(pts, idx, normals, w, tree=None):
    """Step 2b on every particle with its ``_ROW_K`` nearest, and on the particles whose 10 nearest
    lie on a line (rows denser than that) with their ``_ROW_K_LINE`` nearest."""
    N = pts.shape[0]
    out, across = _rows_across(pts, idx[:, :_ROW_K], normals)
    line = np.flatnonzero(~across & (w[:, 1] < _ROW_LINE * w[:, 2]))
    if line.size and N > _ROW_K:
        tree = cKDTree(pts) if tree is None else tree
        nb = tree.query(pts[line], k=min(_ROW_K_LINE, N), workers=get_num_threads())[1]
        out, more = _rows_across(pts, nb, out, line)
        across |= more
    return out, across


def _pca_rows(pts, neighbors):
    """PCA normals of the rows of ``neighbors`` (their own first column is the particle)."""
    local = pts[neighbors] - pts[neighbors[:, :1]]
    local -= local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    return np.linalg.eigh(cov)[1][:, :, 0]


def jet_normals(points: ArrayLike, k: int | None = None, *, degree: int = 2, neighbors: ArrayLike | None = None) -> np.ndarray:
    """Unoriented normals of local polynomial (jet) fits.

    Parameters
    ----------
    points : array_like, shape (N, 3)
    k : int, optional
        Neighbours per particle, itself included (default :data:`DEFAULT_JET_K`
        of the degree; at least the number of coefficients plus 2).
    degree : int
        Total degree of the height function, 1 to 4.
    neighbors : ndarray of int, shape (N, k), optional
        Precomputed neighbour indices, itself first (overrides ``k``).

    Returns
    -------
    ndarray, shape (N, 3)
        Unit normals (signs arbitrary); error ``O(h^degree)`` on smooth surfaces.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(2000)
    >>> n = jet_normals(c.points, degree=2)
    >>> bool(np.abs(np.einsum("ij,ij->i", n, c.normals)).min() > np.cos(np.radians(0.05)))
    True
    """
    pts = as_points("points", points)
    degree = _check_degree(degree)
    if neighbors is None:
        k = DEFAULT_JET_K[degree] if k is None else k
        k = _check_k(k, pts.shape[0], degree)
        _, neighbors = _knn(pts, k)
    w, v = _covariance(pts, neighbors[:, : min(_PCA_K, neighbors.shape[1])])
    return _jet_fit(pts, neighbors, v[:, :, 0], degree)


# ----------------------------------------------------------------------------- winding number
def _winding_numbers(queries, points, normals, area, eps, label, n_labels, theta=0.5, per_cell=32):
    """``out[q, l]``: generalised winding number at ``queries[q]`` of the particles labelled ``l``.

    ``sum_j a_j n_j . (p_j - q) / (4 pi (|p_j - q|^2 + eps_j^2)^(3/2))``, summed exactly over
    cells near the query and as one dipole per (cell, label) over cells whose radius is below
    ``theta`` times their distance (compiled, on threads); without numba a dense numpy sum.
    """
    Q = np.ascontiguousarray(queries, dtype=np.float64)
    P = np.ascontiguousarray(points, dtype=np.float64)
    An = np.ascontiguousarray(area[:, None] * normals)
    eps2 = np.ascontiguousarray(eps**2)
    label = np.ascontiguousarray(label, dtype=np.int64)
    out = np.zeros((Q.shape[0], n_labels))
    if not _jitmod.ENABLED:
        onehot = sp.csr_matrix((np.ones(P.shape[0]), (np.arange(P.shape[0]), label)), shape=(P.shape[0], n_labels))
        for lo in range(0, Q.shape[0], 256):
            r = P[None, :, :] - Q[lo : lo + 256, None, :]
            r2 = np.einsum("qjk,qjk->qj", r, r) + eps2[None, :]
            f = np.einsum("qjk,jk->qj", r, An) / (4 * np.pi * r2 * np.sqrt(r2))
            out[lo : lo + 256] = (onehot.T @ f.T).T
        return out
    # cells of about per_cell particles
    L = max(np.sqrt(per_cell * float(np.mean(area))), 1e-300)
    key = np.floor((P - P.min(axis=0)) / L).astype(np.int64)
    dims = key.max(axis=0) + 1
    lin = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    _, cell = np.unique(lin, return_inverse=True)
    cell = cell.ravel()
    nc = int(cell.max()) + 1
    order = np.argsort(cell, kind="stable").astype(np.int64)
    cstart = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=nc))]).astype(np.int64)
    wsum = np.bincount(cell, weights=area, minlength=nc)
    ccen = np.stack([np.bincount(cell, weights=area * P[:, a], minlength=nc) for a in range(3)], axis=1) / wsum[:, None]
    d2 = np.einsum("ij,ij->i", P - ccen[cell], P - ccen[cell])
    crad2 = np.zeros(nc)
    np.maximum.at(crad2, cell, d2)
    akey = cell * n_labels + label
    ukey, ainv = np.unique(akey, return_inverse=True)
    ainv = ainv.ravel()
    na = ukey.size
    aw = np.bincount(ainv, weights=area, minlength=na)
    apos = np.stack([np.bincount(ainv, weights=area * P[:, a], minlength=na) for a in range(3)], axis=1) / aw[:, None]
    adip = np.stack([np.bincount(ainv, weights=An[:, a], minlength=na) for a in range(3)], axis=1)
    alab = (ukey % n_labels).astype(np.int64)
    aptr = np.searchsorted(ukey // n_labels, np.arange(nc + 1)).astype(np.int64)
    nq = Q.shape[0]
    n_chunks = max(1, min(64, nq // 64))
    bounds = np.linspace(0, nq, n_chunks + 1).astype(np.int64)

    def job(c):
        _jitmod.winding_rows(bounds[c], bounds[c + 1], Q, P, An, eps2, label, order, cstart, ccen, crad2, aptr, alab, apos, adip, theta**2, out)

    run_chunks(job, n_chunks)
    return out


# ----------------------------------------------------------------------------- visibility
def _fibonacci_directions(m):
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


def _visibility(pts, views=None, gamma=None):
    """Sum of the unit directions towards the viewpoints that see each particle, and their count.

    Hidden point removal (Katz, Tal & Basri 2007) from ``views`` viewpoints on a sphere of
    three bounding radii around the centroid: the cloud seen from ``C`` is flipped
    spherically, ``p -> p + 2 (R - |p|) p / |p|`` (``p`` relative to ``C``, ``R`` ``10**gamma``
    times the largest ``|p|``), and the particles on the convex hull of the flipped cloud and
    ``C`` are the visible ones. One hull per viewpoint (a loop over viewpoints only).
    """
    from scipy.spatial import ConvexHull
    from scipy.spatial import QhullError

    views = _VIS_VIEWS if views is None else views
    gamma = _VIS_GAMMA if gamma is None else gamma
    N = pts.shape[0]
    acc = np.zeros((N, 3))
    count = np.zeros(N, dtype=np.int64)
    centre = pts.mean(axis=0)
    radius = float(np.linalg.norm(pts - centre, axis=1).max())
    if radius <= 0:
        return acc, count
    for v in _fibonacci_directions(views):
        q = pts - (centre + 3.0 * radius * v)
        nq = np.linalg.norm(q, axis=1)
        R = float(nq.max()) * 10.0**gamma
        flipped = q + (2.0 * (R - nq) / nq)[:, None] * q
        try:
            hull = ConvexHull(np.vstack([flipped, np.zeros((1, 3))]))
        except (QhullError, ValueError):  # degenerate views see nothing
            continue
        seen = hull.vertices[hull.vertices < N]
        acc[seen] -= q[seen] / nq[seen, None]
        count[seen] += 1
    return acc, count


def _visible_signs(pts, nrm):
    """orient="visible": flip the normals that face away from the viewpoints that see them.

    For a closed surface, a particle seen from a viewpoint ``C`` has its outward normal on
    the side of ``C``. Where at least ``_VIS_MIN_VIEWS`` viewpoints see a particle and its
    normal makes a cosine below ``-_VIS_COS`` with the mean direction towards them, it is
    flipped. Returns the normals and the mask of flipped ones.
    """
    acc, count = _visibility(pts)
    mean_dir = _unit(acc)
    flip = (count >= _VIS_MIN_VIEWS) & (np.einsum("ij,ij->i", mean_dir, nrm) < -_VIS_COS)
    return np.where(flip[:, None], -nrm, nrm), flip


# ----------------------------------------------------------------------------- orientation
def _tree_signs(n_nodes: int, mst: sp.csr_matrix, roots: np.ndarray, edge_sign_fn) -> np.ndarray:
    """Sign of every node relative to its component root along the spanning forest.

    One breadth-first search from a virtual node joined to every root gives all
    tree parents; the signs along the paths are multiplied by pointer jumping.
    """
    sym = (mst + mst.T).tocsr()
    link = sp.coo_matrix((np.ones(roots.size), (roots, np.full(roots.size, n_nodes))), shape=(n_nodes + 1, n_nodes + 1))
    sym = sp.bmat([[sym, None], [None, sp.csr_matrix((1, 1))]], format="csr") + link + link.T
    _, pred = csgraph.breadth_first_order(sym, n_nodes, directed=False, return_predecessors=True)
    pred = pred[:n_nodes]
    idx = np.arange(n_nodes)
    parent = np.where((pred >= 0) & (pred < n_nodes), pred, idx)
    sign = np.ones(n_nodes)
    nodes = np.flatnonzero(parent != idx)
    sign[nodes] = edge_sign_fn(nodes, parent[nodes])
    anc = parent
    while True:  # pointer jumping: sign relative to anc, whose distance doubles each step
        sign = sign * sign[anc]
        nxt = anc[anc]
        if np.array_equal(nxt, anc):
            return sign
        anc = nxt


def _graph_edges(pts, nrm, neighbors):
    """Undirected k-NN edges ``(a, b)`` with the reflection-predicted sign agreement ``s`` and length."""
    N, k = neighbors.shape
    return _pair_edges(pts, nrm, np.repeat(np.arange(N, dtype=np.int64), k), neighbors.ravel().astype(np.int64))


def _orientation_graph(pts, nrm, neighbors):
    """Edges of the orientation graph and the components of the k-NN graph alone.

    The k-NN graph of a cloud sampled much more densely along lines than across them
    (scan lines, the rings of a surface of revolution) falls apart into bands of lines;
    oriented separately, a band has no winding-number evidence of its own (a third of a
    ring-sampled sphere pointed inward). Each particle with another component among its
    ``_BRIDGE_K`` nearest therefore also gets an edge to the nearest such particle; the
    spanning forest then carries the sign across where the reflection rule is confident,
    and the patch check still separates what it is not confident about.
    """
    N = pts.shape[0]
    ko = min(_ORIENT_K, neighbors.shape[1])
    a, b, s, length = _graph_edges(pts, nrm, neighbors[:, :ko])
    n_comp, comps = csgraph.connected_components(sp.coo_matrix((np.ones(a.size), (a, b)), shape=(N, N)), directed=False)
    comps = comps.astype(np.int64)
    if n_comp > 1:
        tree = cKDTree(pts)
        _, idx = _knn(pts, min(_BRIDGE_K, N), tree)
        other = comps[idx] != comps[:, None]
        rows = np.flatnonzero(other.any(axis=1))
        cols = idx[rows, other[rows].argmax(axis=1)].astype(np.int64)
        # small components with no other one among their particles' nearest (a tight ring
        # at a pole): the nearest particle outside, searched from a few of their particles
        size = np.bincount(comps, minlength=n_comp)
        lonely = np.setdiff1d(np.flatnonzero(size <= _BRIDGE_MAX_SIZE), comps[rows])
        extra_r, extra_c = [rows], [cols]
        for c in lonely[:_BRIDGE_MAX_LONELY]:  # a loop over components, each one batched query
            members = np.flatnonzero(comps == c)
            src = members[np.linspace(0, members.size - 1, min(members.size, 16)).astype(np.int64)]
            dist_c, idx_c = tree.query(pts[src], k=min(int(size[c]) + 1, N))
            out = comps[idx_c] != c
            ok = out.any(axis=1)
            if ok.any():
                first = out.argmax(axis=1)
                best = np.argmin(np.where(ok, dist_c[np.arange(src.size), first], np.inf))
                extra_r.append(src[best : best + 1])
                extra_c.append(idx_c[best : best + 1, first[best]].astype(np.int64))
        rows, cols = np.concatenate(extra_r), np.concatenate(extra_c)
        if rows.size:
            knn_rows = np.repeat(np.arange(N, dtype=np.int64), ko)
            a, b, s, length = _pair_edges(pts, nrm, np.concatenate([knn_rows, rows]),
                                          np.concatenate([neighbors[:, :ko].ravel().astype(np.int64), cols]))
    return a, b, s, length, comps


def _pair_edges(pts, nrm, rows, cols):
    """Undirected edges of the pairs ``(rows, cols)``, unique and sorted by key, with ``s`` and length."""
    N = pts.shape[0]
    off = rows != cols
    a, b = np.minimum(rows[off], cols[off]), np.maximum(rows[off], cols[off])
    key = np.unique(a * N + b)
    a, b = key // N, key % N
    e = pts[b] - pts[a]
    length = np.linalg.norm(e, axis=1)
    e = e / np.where(length > 0, length, 1.0)[:, None]
    pred = nrm[a] - 2.0 * np.einsum("ij,ij->i", nrm[a], e)[:, None] * e  # n_a reflected in the bisector plane
    return a, b, np.einsum("ij,ij->i", pred, nrm[b]), length


def _spanning_forest(N, a, b, s, length):
    """Maximum-confidence spanning forest: its signs relative to each root, edges, components."""
    conf = np.abs(s)
    scale = float(np.median(length)) if length.size else 1.0
    cost = (1.0 - conf) + 1e-3 * length / max(scale, 1e-300) + 1e-12  # never 0 (stored zeros are no edges)
    G = sp.coo_matrix((cost, (a, b)), shape=(N, N)).tocsr()
    G = G.maximum(G.T)
    n_comp, labels = csgraph.connected_components(G, directed=False)
    mst = csgraph.minimum_spanning_tree(G).tocoo()
    ta, tb = mst.row.astype(np.int64), mst.col.astype(np.int64)
    # the sign and confidence of each tree edge, looked up by its key
    key = a * N + b
    tkey = np.minimum(ta, tb) * N + np.maximum(ta, tb)
    pos = np.searchsorted(key, tkey)  # key is sorted (np.unique)
    tsign = np.where(s[pos] < 0, -1.0, 1.0)
    tconf = conf[pos]
    roots = np.unique(labels, return_index=True)[1]
    T = sp.coo_matrix((tsign, (ta, tb)), shape=(N, N)).tocsr()
    T = T + T.T

    def edge_sign(child, par):
        return np.asarray(T[child, par]).ravel()

    sign = _tree_signs(N, mst.tocsr(), roots, edge_sign)
    return sign, labels.astype(np.int64), ta, tb, tconf


def _patches(N, ta, tb, tconf, flag):
    """Cut the spanning forest into patches at doubtful edges and where ``flag`` changes."""
    conf_cut = tconf < _TRUST
    flag_cut = flag[ta] != flag[tb]
    keep = ~(conf_cut | flag_cut)

    def comps(keep):
        T = sp.coo_matrix((np.ones(int(keep.sum())), (ta[keep], tb[keep])), shape=(N, N))
        return csgraph.connected_components(T, directed=False)

    n_p, lab = comps(keep)
    for _ in range(3):  # merge tiny patches back through their doubtful (not flag) edges
        size = np.bincount(lab, minlength=n_p)
        small = ((size[lab[ta]] < _MIN_PATCH) | (size[lab[tb]] < _MIN_PATCH)) & ~keep & ~flag_cut
        if not small.any():
            break
        keep = keep | small
        n_p, lab = comps(keep)
    if n_p > _MAX_PATCHES:  # a forest: restoring any cut edge merges two patches
        cut = np.flatnonzero(~keep)
        prio = tconf[cut] - 2.0 * flag_cut[cut]  # restore confident, not-flag cuts first
        keep = keep.copy()
        keep[cut[np.argsort(-prio, kind="stable")[: n_p - _MAX_PATCHES]]] = True
        n_p, lab = comps(keep)
    return n_p, lab.astype(np.int64)


def _best_signs(H, g, blocks, margin=None):
    """Greedy minimum of ``s^T H s - 2 g^T s`` over s in {-1, 1}^n from s = 1 (diagonal of H ignored).

    Moves: single entries, and whole blocks (rows of the 0/1 matrix ``blocks``). An entry
    with a ``margin`` leaves +1 only where that lowers the energy by more than its margin.
    """
    H = H.copy()
    np.fill_diagonal(H, 0.0)
    s = np.ones(H.shape[0])
    tol = 1e-12 * (np.abs(H).sum() + np.abs(g).sum() + 1e-300)
    for _ in range(4 * H.shape[0] + 20):
        Hs = H @ s
        d1 = 4.0 * s * (g - Hs)  # energy change of flipping one entry
        if margin is not None:
            d1 = d1 + np.where(s > 0, margin, 0.0)
        j = int(np.argmin(d1))
        if d1[j] < -tol:
            s[j] = -s[j]
            continue
        X = blocks * s[None, :]
        dB = -4.0 * X @ Hs + 4.0 * np.einsum("bi,bi->b", X @ H, X) + 4.0 * X @ g
        b = int(np.argmin(dB)) if dB.size else -1
        if b >= 0 and dB[b] < -tol:
            s[blocks[b] > 0] *= -1.0
            continue
        break
    return s


def _outward(pts, nrm, neighbors, distances, noise=0.0):
    """Consistent, then globally checked outward orientation (module notes, steps 3-4).

    Returns the oriented normals, the connected component of every particle and
    the orientation confidence in [0, 1].
    """
    N = pts.shape[0]
    ko = min(_ORIENT_K, neighbors.shape[1])
    a, b, s, length, comps = _orientation_graph(pts, nrm, neighbors)
    sign, _, ta, tb, tconf = _spanning_forest(N, a, b, s, length)
    if _CUT_THIN:  # tree edges where the reflection rule and the parallel rule disagree cross a thin part: patches decide
        e = pts[tb] - pts[ta]
        e = e / np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
        pred = nrm[ta] - 2.0 * np.einsum("ij,ij->i", nrm[ta], e)[:, None] * e
        refl = np.einsum("ij,ij->i", pred, nrm[tb])
        par = np.einsum("ij,ij->i", nrm[ta], nrm[tb])
        tconf = np.where((refl * par < 0) & (np.abs(par) > _CUT_THIN), 0.0, tconf)
    n = nrm * sign[:, None]
    n_comp = int(comps.max()) + 1 if N else 0
    # area and probe offset per particle from the local spacing
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    h = np.sqrt(area)
    if N <= _MAX_PROBES:
        probes = np.arange(N)
    else:
        probes = np.sort(np.random.default_rng(0).choice(N, _MAX_PROBES, replace=False))
    delta = _PROBE_OFFSET * h[probes]
    if _THICK_PROBE > 0:  # probes stay inside thin parts: at most this fraction of the height across
        L = pts[neighbors[probes, 1:]] - pts[probes][:, None, :]
        z = np.abs(np.einsum("nkj,nj->nk", L, nrm[probes]))
        par = np.abs(np.einsum("nkj,nj->nk", nrm[neighbors[probes, 1:]], nrm[probes])) > _THICK_PAR
        steep = z * z > np.maximum(np.einsum("nkj,nkj->nk", L, L) - z * z, 0.0)
        floor = _THICK_NOISE * noise * distances[probes, min(_THIN_K, distances.shape[1]) - 1]
        across = np.where(par & steep & (z > floor[:, None]), z, np.inf).min(axis=1)
        delta = np.maximum(np.minimum(delta, _THICK_PROBE * across), _THICK_FLOOR * delta)
    if _CALIBRATE:
        # the jump w_in - w_out across the particle is its local dipole density over the true
        # one (the far field cancels in the difference, whatever its orientation): rescale the areas
        q = np.vstack([pts[probes] - delta[:, None] * n[probes], pts[probes] + delta[:, None] * n[probes]])
        W = _winding_numbers(q, pts, n, area, 0.2 * h, np.zeros(N, dtype=np.int64), 1)[:, 0]
        jump = np.abs(W[: probes.size] - W[probes.size :])
        near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
        # areas are only ever reduced: in a noisy layer the probes sit among the points and
        # the jump is too small (enlarged areas flipped 150 of 4000 on a torus with noise of
        # 0.3 spacings, measured)
        jump = np.clip(np.median(jump[near][neighbors[:, :ko]], axis=1), 1.0, 4.0)
        area = area / jump
    omega = area[probes] * (N / probes.size)
    sheet_d = _closed_sheets(pts, n, neighbors, probes, delta, area, h) if _SHEETS else None
    flag = np.zeros(N, dtype=bool)
    D = np.ones(probes.size)
    S = np.ones(probes.size)
    for rnd in range(_ROUNDS):
        n_p, lab = _patches(N, ta, tb, tconf, flag if sheet_d is None else flag + 3 * (sheet_d + 1))
        pp = lab[probes]
        q = np.vstack([pts[probes] - delta[:, None] * n[probes], pts[probes] + delta[:, None] * n[probes]])
        W = _winding_numbers(q, pts, n, area, 0.2 * h, lab, n_p)
        if sheet_d is not None:  # a closed sheet's probes see its own field only (module notes, step 4)
            patch_sheet = np.full(n_p, -1, dtype=np.int64)
            patch_sheet[lab] = sheet_d
            own = sheet_d[probes]
            other = (own[:, None] >= 0) & (patch_sheet[None, :] != own[:, None])
            W[np.vstack([other, other])] = 0.0
        w_in, w_out = W[: probes.size], W[probes.size :]
        Dm, Sm = w_in - w_out, w_in + w_out
        M = np.zeros((n_p, n_p))
        np.add.at(M, pp, omega[:, None] * Dm)
        H = Dm.T @ (omega[:, None] * Dm) + Sm.T @ (omega[:, None] * Sm) - (M + M.T)
        g = omega @ Sm
        comp_of_patch = np.zeros(n_p, dtype=np.int64)
        comp_of_patch[lab] = comps
        blocks = np.zeros((n_comp, n_p)) if n_comp > 1 else np.zeros((0, n_p))
        if n_comp > 1:
            blocks[comp_of_patch, np.arange(n_p)] = 1.0
        sP = _best_signs(H, g, blocks)
        if _FLAG_S_HIGH is not None and rnd > 0:
            # patches cut for both probes inside (flag 2) flip only where the flip explains it, i.e. their
            # probes are then no longer both inside (a part inside another shell reads both inside either way)
            wt = np.bincount(pp, weights=omega, minlength=n_p)
            high = (np.bincount(pp, weights=omega * (flag[probes] == 2), minlength=n_p) > 0.5 * wt) & (sP < 0)
            if high.any():
                sw = sP[pp] < 0
                s_new = np.where(sw, w_out @ sP, w_in @ sP) + np.where(sw, w_in @ sP, w_out @ sP)
                s_old = w_in.sum(axis=1) + w_out.sum(axis=1)
                excess_new = np.bincount(pp, weights=omega * (s_new - 1.0), minlength=n_p)
                excess_old = np.bincount(pp, weights=omega * (s_old - 1.0), minlength=n_p)
                stay = high & (excess_new > np.where(excess_old > 0, _FLAG_S_EXPLAIN * excess_old, 0.0))
                if stay.any():
                    sP = _best_signs(H, g, blocks, np.where(stay, np.inf, 0.0))
        n = n * sP[lab][:, None]
        # field of the new orientation at the (possibly swapped) probes
        sw = sP[pp] < 0
        wi = np.where(sw, w_out @ sP, w_in @ sP)
        wo = np.where(sw, w_in @ sP, w_out @ sP)
        D, S = wi - wo, wi + wo
        if rnd > 0 and np.all(sP > 0):
            break
        bad = ((D < 0) | (S < _FLAG_S)).astype(np.int64)
        if _FLAG_S_HIGH is not None:  # a class of its own: cut from both the good and the flipped probes
            bad[(bad == 0) & (S > _FLAG_S_HIGH)] = 2
        near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
        flag = bad[near]
        if _FLAG_S_HIGH is not None and _HIGH_MIN > 1 and (flag == 2).any():  # only sizeable both-inside regions
            both = (flag[ta] == 2) & (flag[tb] == 2)
            _, hl = csgraph.connected_components(sp.coo_matrix((np.ones(int(both.sum())), (ta[both], tb[both])), shape=(N, N)),
                                                 directed=False)
            hsize = np.bincount(hl[flag == 2], minlength=N)
            flag[(flag == 2) & (hsize[hl] < _HIGH_MIN)] = 0
    # flat sheets: no winding-number evidence either way -> mean normal with a positive largest component
    pc = comps[probes]
    evidence = np.bincount(pc, weights=omega * S, minlength=n_comp)
    total = np.bincount(pc, weights=omega, minlength=n_comp)
    flat = np.abs(evidence) <= 0.05 * total
    if flat.any():
        mean_n = np.stack([np.bincount(comps, weights=n[:, i], minlength=n_comp) for i in range(3)], axis=1)
        big = mean_n[np.arange(n_comp), np.abs(mean_n).argmax(axis=1)]
        cs = np.where(flat & (big < 0), -1.0, 1.0)
        n = n * cs[comps][:, None]
    # isolated particles against a clear majority of their neighbours (reflection rule) are flipped
    for _ in range(2):
        a, b, s, _ = _graph_edges(pts, n, neighbors[:, :ko])
        V = sp.coo_matrix((np.r_[s, s], (np.r_[a, b], np.r_[b, a])), shape=(N, N)).tocsr()
        vote = np.asarray(V.sum(axis=1)).ravel()
        weight = np.asarray(abs(V).sum(axis=1)).ravel()
        flip = vote < -0.5 * weight
        if not flip.any():
            break
        n[flip] *= -1.0
    near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
    oconf = np.clip(4.0 * D, 0.0, 1.0)[near]  # D = 1 inside a closed surface, about 1/2 at the rim of an open sheet
    oconf[np.abs(vote) < 0.5 * weight] *= 0.5  # neighbours split on the sign
    return n, comps, oconf


def _closed_sheets(pts, nrm, neighbors, probes, delta, area, h):
    """Label of the closed sheet of every particle (-1: none), or None: nothing to judge apart.

    Sheets are the components of the k-NN graph kept where both ends lie near each other's
    tangent plane with nearly parallel normal lines, without junctions and bridges: surfaces
    that cross (interpenetrating parts of a model) fall apart there. A sheet of at least
    ``_SHEET_MIN`` particles is closed where its own winding number, with its propagated signs,
    is decisive at its probes (``|mean(w_in + w_out)| >= _SHEET_CLOSED``) and it is not wholly
    inside the others. None unless two closed sheets exist and one crosses another (module
    notes, step 4, surfaces that pass through each other).
    """
    N = pts.shape[0]
    ko = min(_ORIENT_K, neighbors.shape[1])
    rows = np.repeat(np.arange(N, dtype=np.int64), ko - 1)
    cols = neighbors[:, 1:ko].ravel().astype(np.int64)
    L = pts[cols] - pts[rows]
    l2 = np.einsum("ij,ij->i", L, L)
    zi = np.abs(np.einsum("ij,ij->i", L, nrm[rows]))
    zj = np.abs(np.einsum("ij,ij->i", L, nrm[cols]))
    t2 = _SHEET_TAN**2
    par = np.abs(np.einsum("ij,ij->i", nrm[rows], nrm[cols])) > _SHEET_DOT
    edge = (par & (zi * zi <= t2 * np.maximum(l2 - zi * zi, 0.0)) & (zj * zj <= t2 * np.maximum(l2 - zj * zj, 0.0))).reshape(N, ko - 1)
    # a junction: its sheet neighbours are not parallel among themselves (a normal averaged over two
    # crossing sheets) and their normals do not follow one shape operator (on one strongly curved
    # surface the normal turns linearly with the position; across a crossing it jumps)
    nb = nrm[neighbors[:, 1:ko]] * edge[:, :, None]
    G = np.abs(np.einsum("nkj,nlj->nkl", nb, nb))
    junction = np.any(edge[:, :, None] & edge[:, None, :] & (G < _SHEET_JUNCTION), axis=(1, 2))
    if _SHEET_SHAPE and junction.any():
        r = np.flatnonzero(junction)
        t1, t2 = _tangents(nrm[r])
        Lr = L.reshape(N, ko - 1, 3)[r]
        x, y = np.einsum("nkj,nj->nk", Lr, t1), np.einsum("nkj,nj->nk", Lr, t2)
        nj = nrm[neighbors[r, 1:ko]]
        nj = nj * np.where(np.einsum("nkj,nj->nk", nj, nrm[r]) < 0, -1.0, 1.0)[:, :, None]
        u, v = np.einsum("nkj,nj->nk", nj, t1), np.einsum("nkj,nj->nk", nj, t2)
        wgt = edge[r].astype(np.float64)
        # u = a x + b y + u0, v = b x + c y + v0 (a symmetric shape operator and an offset), least squares
        Z = np.zeros_like(x)
        O = np.ones_like(x)
        A = np.concatenate([np.stack([x, y, Z, O, Z], axis=2), np.stack([Z, x, y, Z, O], axis=2)], axis=1)
        rhs = np.concatenate([u, v], axis=1)
        W2 = np.concatenate([wgt, wgt], axis=1)
        M = np.einsum("nki,nk,nkj->nij", A, W2, A) + 1e-12 * np.eye(5)[None]
        coef = np.linalg.solve(M, np.einsum("nki,nk,nk->ni", A, W2, rhs)[..., None])[..., 0]
        res = rhs - np.einsum("nki,ni->nk", A, coef)
        dev = rhs - (np.einsum("nk,nk->n", W2, rhs) / np.maximum(W2.sum(axis=1), 1e-300))[:, None]
        rel = np.sqrt(np.einsum("nk,nk->n", W2, res * res) / np.maximum(np.einsum("nk,nk->n", W2, dev * dev), 1e-300))
        junction[r[rel < _SHEET_SHAPE]] = False
    if junction.mean() > _SHEET_MAX_JUNCTION:  # coarse or noisy: the sheets are not trusted
        return None
    keep = (edge & ~junction[:, None]).ravel() & ~junction[cols]
    A = sp.coo_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(N, N)).tocsr()
    A = ((A + A.T) > 0).astype(np.float64)
    for _ in range(_SHEET_PRUNE):  # edges in fewer than _SHEET_SUPPORT triangles are bridges, not sheet
        A = A.multiply((A @ A).multiply(A) >= _SHEET_SUPPORT).tocsr()
    n_s, sheet = csgraph.connected_components(A, directed=False)
    size = np.bincount(sheet, minlength=n_s)
    big = np.flatnonzero(size >= max(_SHEET_MIN, _SHEET_FRACTION * N))
    if big.size < 2:
        return None
    label = np.full(n_s, -1, dtype=np.int64)
    label[big] = np.arange(big.size)
    lab = label[sheet]
    # particles left out (junctions, small pieces: the cap of a surface cut off where another
    # crosses it) join the sheet of a neighbour with a parallel normal line, over a few rings
    nbr = neighbors[:, 1:ko]
    for _ in range(_SHEET_GROW):
        cand = np.where(edge & (lab[nbr] >= 0), lab[nbr], -1)
        has = (lab < 0) & (cand >= 0).any(axis=1)
        if not has.any():
            break
        lab[has] = cand[has, (cand[has] >= 0).argmax(axis=1)]
    lab = np.where(lab < 0, big.size, lab)
    # each sheet oriented consistently on its own edges (propagation over the whole graph may have
    # mixed its signs where it crosses another), for the test of closure below
    inner = edge.ravel() & (lab[rows] == lab[cols]) & (lab[rows] < big.size)
    ri, ci = rows[inner], cols[inner]
    Lu = L[inner] / np.sqrt(np.maximum(l2[inner], 1e-300))[:, None]
    pred = nrm[ri] - 2.0 * np.einsum("ij,ij->i", nrm[ri], Lu)[:, None] * Lu  # the reflection rule of step 3
    sgn = np.where(np.einsum("ij,ij->i", pred, nrm[ci]) < 0, -1.0, 1.0)
    Sg = sp.coo_matrix((sgn, (ri, ci)), shape=(N, N)).tocsr()
    Sg = Sg + Sg.T  # (a pair found from both ends has the same sign twice)
    roots = np.unique(csgraph.connected_components(Sg, directed=False)[1], return_index=True)[1]
    sn = nrm * _tree_signs(N, Sg, roots, lambda child, par: np.sign(np.asarray(Sg[child, par]).ravel()))[:, None]
    q = np.vstack([pts[probes] - delta[:, None] * sn[probes], pts[probes] + delta[:, None] * sn[probes]])
    W = _winding_numbers(q, pts, sn, area, 0.2 * h, lab, big.size + 1)
    own = lab[probes]
    m = own < big.size
    S = np.zeros(probes.size)
    S[m] = W[: probes.size][m, own[m]] + W[probes.size :][m, own[m]]
    w = area[probes] * m
    wt = np.maximum(np.bincount(own[m], weights=w[m], minlength=big.size), 1e-300)
    mean = np.bincount(own[m], weights=(w * S)[m], minlength=big.size) / wt
    closed = np.abs(mean) >= _SHEET_CLOSED
    # the share of a sheet's probes inside the other sheets' field: wholly inside (the inner wall
    # of a hollow part), it keeps the whole field, whose answer (facing the cavity) is the convention
    # there; partly inside, it crosses another surface
    Wsum = 0.5 * (W[: probes.size].sum(axis=1) + W[probes.size :].sum(axis=1))
    inside = np.zeros(probes.size, dtype=bool)
    inside[m] = np.abs(Wsum[m] - 0.5 * S[m]) > 0.5
    frac_in = np.bincount(own[m], weights=(w * inside)[m], minlength=big.size) / wt
    closed &= (frac_in < _SHEET_NESTED) | (np.abs(mean) < _SHEET_SEALED)
    # only where closed sheets pass through each other is the whole field misleading; touching
    # pieces of one coarse surface are left to it
    if closed.sum() < 2 or not np.any(closed & (frac_in >= _SHEET_CROSS)):
        return None
    ids = np.full(big.size + 1, -1, dtype=np.int64)
    ids[np.flatnonzero(closed)] = np.arange(int(closed.sum()))
    return ids[lab]


def _consistent(pts, nrm, neighbors):
    N = pts.shape[0]
    a, b, s, length, comps = _orientation_graph(pts, nrm, neighbors)
    sign, *_ = _spanning_forest(N, a, b, s, length)
    return nrm * sign[:, None], comps


def _check_orient(orient):
    if not isinstance(orient, str):
        view = np.asarray(orient, dtype=np.float64) if np.ndim(orient) == 1 else np.zeros(0)
        if view.shape != (3,) or not np.all(np.isfinite(view)):
            raise ValueError(f"orient must be one of {list(ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
        return view
    if orient not in ORIENTATIONS:
        raise ValueError(f"orient must be one of {list(ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
    return orient


def _orient(pts, nrm, neighbors, distances, orient, noise=0.0):
    """Orient unit normals; returns (normals, component labels, orientation confidence)."""
    N = pts.shape[0]
    if not isinstance(orient, str):
        s = np.sign(np.einsum("ij,ij->i", orient - pts, nrm))
        s[s == 0] = 1.0
        return nrm * s[:, None], np.zeros(N, dtype=np.int64), np.ones(N)
    if orient == "none":
        _, _, _, _ = None, None, None, None
        n, comps = nrm.copy(), _consistent(pts, nrm, neighbors)[1]
        return n, comps, np.ones(N)
    if orient == "consistent":
        n, comps = _consistent(pts, nrm, neighbors)
        return n, comps, np.ones(N)
    return _outward(pts, nrm, neighbors, distances, noise)  # "outward" and "visible" (its last pass follows)


def orient_normals(points: ArrayLike, normals: ArrayLike, k: int = DEFAULT_K, *, orient: str | ArrayLike = "outward",
                   neighbors: ArrayLike | None = None, distances: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Flip unoriented normals to a consistent (and, for closed surfaces, outward) orientation.

    Parameters
    ----------
    points, normals : array_like, shape (N, 3)
    k : int
        Neighbours per particle of the orientation graph (itself included).
    orient : {"outward", "visible", "consistent", "none"} or array_like, shape (3,)
        "consistent": propagation over the maximum-confidence spanning tree only
        (each component's root keeps its sign); "outward": then the winding-number
        check, which repairs patches and orients every component outward (module
        notes); "visible": "outward", then every normal that faces away from the
        viewpoints around the cloud that see it is flipped (closed surfaces with
        thin parts only; module notes, step 8); a point (3,): flip every normal
        towards that viewpoint (single-view scans; no propagation); "none": return
        the normals unchanged.
    neighbors, distances : ndarray, shape (N, k), optional
        Precomputed k-nearest-neighbour indices (itself first) and distances.

    Returns
    -------
    normals : ndarray, shape (N, 3)
    labels : ndarray of int, shape (N,)
        Connected component of every particle in the k-nearest-neighbour graph.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(500)
    >>> signs = np.where(np.arange(500) % 3 == 0, -1.0, 1.0)[:, None]
    >>> n, labels = orient_normals(cloud.points, signs * cloud.normals)
    >>> bool(np.allclose(n, cloud.normals)), int(labels.max()) + 1
    (True, 1)
    """
    pts = as_points("points", points)
    nrm = as_points("normals", normals)
    N = pts.shape[0]
    if nrm.shape != pts.shape:
        raise ValueError(f"normals must have shape {pts.shape} to match points, got shape {nrm.shape}")
    nrm = _unit(nrm)
    orient = _check_orient(orient)
    if neighbors is None or distances is None:
        k = check_int("k", k, minimum=2)
        distances, neighbors = _knn(pts, min(k, N))
    n, labels, _ = _orient(pts, nrm, np.asarray(neighbors), np.asarray(distances), orient)
    if isinstance(orient, str) and orient == "visible":
        n, _ = _visible_signs(pts, n)
    return n, labels


# ----------------------------------------------------------------------------- public entry
def _check_degree(degree) -> int:
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)):
        raise TypeError(f"degree must be an integer from 1 to 4, got {type(degree).__name__} {degree!r}")
    if not 1 <= int(degree) <= 4:
        raise ValueError(f"degree must be an integer from 1 to 4, got {degree!r}")
    return int(degree)


def _check_k(k, N, degree=None) -> int:
    k = check_int("k", k, minimum=3)
    if degree is not None and k < _n_coefficients(degree) + 2:
        raise ValueError(f"k must be at least {_n_coefficients(degree) + 2} for a degree-{degree} jet fit, got {k}")
    if k > N:
        raise ValueError(f"k must be at most the number of points {N}, got {k}")
    return k


def estimate_normals(points: ArrayLike, k: int | None = None, *, orient: str | ArrayLike = "outward",
                     return_confidence: bool = False, method: str = "jet", degree: int | None = None,
                     refine: bool = True, poles: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Estimate unit normals of a point cloud: fitted, consistently oriented and outward.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        At least 3 distinct points; N >= k.
    k : int, optional
        Nearest neighbours per particle, itself included. Default: for
        ``method="jet"`` :data:`DEFAULT_JET_K` of the degree (12 for degree 2; at
        least the number of coefficients plus 2), for ``method="pca"`` 16
        (capped at N). Use more on noisy clouds.
    orient : {"outward", "visible", "consistent", "none"} or array_like, shape (3,)
        See :func:`orient_normals`. "outward" (the default) propagates a consistent
        orientation and checks it globally with the winding number, so that every
        component points out. "visible" then corrects the signs by visibility from
        outside (after steps 5-7): for closed surfaces with thin parts; wrong on open
        or nested surfaces seen from inside through an opening (module notes, step 8).
    return_confidence : bool
        Also return the per-particle confidence (see the module notes).
    method : {"jet", "pca"}
        "jet" (default): local polynomial fits, order ``degree`` on smooth
        surfaces; "pca": the covariance normal (first order; the former default).
    degree : int, optional
        Degree of the jet, 1 to 4 (default 2: second order; 3 and 4 for
        high-order schemes). Only with ``method="jet"``.
    refine : bool
        After orientation, refit each particle with only the neighbours whose
        normal agrees with its own (no averaging across creases or thin parts),
        then choose the direction of undetermined normals (thin or anisotropically
        sampled parts) among fits on several neighbourhoods by agreement with the
        neighbours (module notes, steps 5 and 7; at least 24 points).
        Only with ``method="jet"``; ignored when ``orient="none"``.
    poles : bool
        Also use the Voronoi poles of the cloud (one 3D Delaunay triangulation,
        :func:`~manifold_sph.scans.poles.voronoi_poles`): the pole line and a fit in its
        frame as further candidates of step 7, and a last sign check by the winding
        number at each particle's two poles (module notes, step 9). Fewer wrong
        orientations at thin parts of coarse models sampled at their vertices (cow
        51 -> 39 normals inward, beetle-alt 142 -> 74 disagreeing with the mesh; smaller,
        mixed gains on random samples of the same surfaces, worse on noisy clouds), at the cost of
        the triangulation (2.5 times the default's time on 35,000 points); not the default. Only with
        ``orient="outward"`` or ``"visible"`` (ignored otherwise) and at least 5
        points spanning a volume (ignored on planar clouds).

    Returns
    -------
    normals : ndarray, shape (N, 3)
    confidence : ndarray, shape (N,), only if ``return_confidence``
        In [0, 1]; below about 0.5 the normal or its sign is poorly determined.

    Raises
    ------
    ValueError
        On a bad ``points`` array, ``k``, ``orient``, ``method`` or ``degree``.
    TypeError
        On a ``k`` or ``degree`` that is not an integer, or a non-bool flag.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(1000)
    >>> n, conf = estimate_normals(cloud.points, return_confidence=True)
    >>> float(np.einsum("ij,ij->i", n, cloud.normals).min().round(3)), bool(conf.min() > 0.9)
    (1.0, True)
    """
    pts = as_points("points", points)
    N = pts.shape[0]
    if N < 3:
        raise ValueError(f"points must hold at least 3 points to estimate normals, got {N}")
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    for name, flag in (("return_confidence", return_confidence), ("refine", refine), ("poles", poles)):
        if not isinstance(flag, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(flag).__name__} {flag!r}")
    if method == "pca":
        if degree is not None:
            raise ValueError(f"degree applies only to method='jet', got degree={degree!r} with method='pca'")
        k = _check_k(min(DEFAULT_K, N) if k is None else k, N)
    else:
        degree = _check_degree(2 if degree is None else degree)
        weighted = k is None  # an explicit k (e.g. a larger one for noise) is fitted with uniform weights
        if k is None:
            k = DEFAULT_JET_K[degree]
            if k > N:
                raise ValueError(f"points must hold at least {k} points for a degree-{degree} jet fit with the default k, got {N}")
        k = _check_k(k, N, degree)
    orient = _check_orient(orient)
    consensus = method == "jet" and bool(refine) and not (isinstance(orient, str) and orient == "none")
    k_consensus = max(max(kc for kc, _ in _CONSENSUS_CANDIDATES), _ROW_K) if consensus else 0
    dist, idx = _knn(pts, min(max(k, _ORIENT_K, _SCALE_K[-1] if return_confidence else 0, k_consensus), N))
    refine = bool(refine) and not (isinstance(orient, str) and orient == "none")
    vor = None
    if poles and isinstance(orient, str) and orient in ("outward", "visible"):
        from .poles import voronoi_poles

        try:
            vor = voronoi_poles(pts)
        except ValueError:  # a planar cloud: no volume, no poles
            vor = None
    if method == "pca":
        w, v = _covariance(pts, idx[:, :k])
        nrm = v[:, :, 0]
    else:
        # degree 3/4: fit and orient at degree 2 first (its smaller neighbourhood is
        # the robust one on thin parts), then refit at the full degree (step 6)
        base_deg, kb = (degree, k) if degree <= 2 else (2, min(k, DEFAULT_JET_K[2]))
        w, v = _covariance(pts, idx[:, : min(k, _PCA_K)])
        base_res = np.zeros(N)
        base_w = _distance_weights(pts, idx[:, :kb]) if _JET_WEIGHT and weighted else None
        nrm = _jet_fit(pts, idx[:, :kb], v[:, :, 0], base_deg, weights=base_w, residual=base_res)
        refit_w = base_w  # step 5: sharper where the residual is bias, not noise (_sharpened_weights)
        if refine and base_w is not None and _SHARP_WEIGHT != _JET_WEIGHT and base_deg == 2 and kb >= _n_coefficients(3) + 2:
            refit_w = _sharpened_weights(pts, idx[:, :kb], v[:, :, 0], base_w, base_res)
        across = np.zeros(N, dtype=bool)
        if refine and _ROW_STEEP and idx.shape[1] >= _ROW_K:
            nrm, across = _rows_step(pts, idx, nrm, w)
    conf = _shape_confidence(w)
    before = None
    noise = float(np.median(base_res)) if method == "jet" else 0.0  # the cloud's relative fit residual
    nrm, _, oconf = _orient(pts, nrm, idx, dist, orient, noise)
    if method == "jet":
        if refine:  # the normals of step 2b are kept (their neighbours lie on their own row)
            nrm = np.where(across[:, None], nrm, _refit(pts, idx[:, :kb], nrm, base_deg, residual=base_res, weights=refit_w))
        one_sided = None
        if degree > 2:
            hi, one_sided = _high_order(pts, idx[:, :k], nrm, base_res, degree, refine)
            nrm = np.where(across[:, None], nrm, hi)
        if consensus:
            if vor is None:
                nrm, before = _consensus(pts, idx, nrm, one_sided)
            else:
                nrm, before = _consensus(pts, idx, nrm, one_sided, pole=vor[0])
    if vor is not None:  # step 9: signs from the winding number at the Voronoi poles
        nrm, _ = _pole_signs(pts, nrm, dist, vor)
    if isinstance(orient, str) and orient == "visible":
        nrm, _ = _visible_signs(pts, nrm)
    if not return_confidence:
        return nrm
    scale = _scale_confidence(pts, idx, nrm, before)
    if method == "jet" and across.any():  # step 2b: the row normals disagree with the nearest points'
        rows = np.flatnonzero(across)  # fits by construction; trusted where no point lies steeply on both sides
        up, down, *_ = _steep(pts, idx[rows, :_ROW_K], nrm, rows)
        scale[rows[np.minimum(up, down) == 0]] = 1.0
    return nrm, conf * oconf * scale * _thin_confidence(pts, idx[:, :_THIN_K], dist[:, :_THIN_K], nrm, noise)
