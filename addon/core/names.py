"""The names a solve is asked for by: estimators, exit points, samplings, direct lights, methods, stop
rules and stop reasons (each method's policy is its module's in ``methods``)."""

# The paper's two estimators.
FINITE = "finite"                    # Phi_T: constant power, die-or-survive with R_bar at each hit
BIASED_INFINITE = "biased_infinite"  # power times R at each hit, cut below the threshold t
ESTIMATORS = (FINITE, BIASED_INFINITE)

# Where the next ray leaves a hit patch from.
EXIT_RANDOM = "random"  # a new uniform point of the patch: the paper's discrete method
EXIT_HIT = "hit"        # the point hit: particle tracing
EXIT_POINTS = (EXIT_RANDOM, EXIT_HIT)

# How sources and first rays are drawn.
INDEPENDENT = "independent"  # the paper's: what the predicted path counts are derived for
STRATIFIED = "stratified"    # paths allotted in proportion to power, low-discrepancy first rays
SAMPLINGS = (INDEPENDENT, STRATIFIED)

# Where the direct light comes from (the first bounce).
SHOT = "shot"          # the paper's: every path's first hit scores it
GATHERED = "gathered"  # each patch gathers it by shadow rays; the walks shoot only its reflection
DIRECT_LIGHTS = (SHOT, GATHERED)

# How the light is carried from patch to patch.
WALK = "walk"      # the paper's: shooting random walks, path by path
JACOBI = "jacobi"  # stochastic Jacobi iteration: shot generation by generation, stratified (jacobi.py)
TWO_WAY = "two_way"  # stochastic Jacobi with every ray shooting and gathering, a control variate (two_way.py)
METHODS = (WALK, JACOBI, TWO_WAY)
AUTO = "auto"      # the two-way iteration where its chunks give every patch enough rays, else the walk (methods.automatic)

# When a solve with an error target stops.
PREDICTED = "predicted"  # after the paths formula (2)/(3) predicts for the target
MEASURED = "measured"    # once the batch-means estimate meets the target
STOP_RULES = (PREDICTED, MEASURED)

# What an error target's relative RMS is relative to (the mean reflected radiosity).
SCALE_PAPER = "paper"        # b_ave = R_ave Phi_T / (A_T (1 - R_ave)): the paper's, a closed scene's mean
SCALE_MEASURED = "measured"  # the run's own area-weighted mean of b: light that leaves the scene is not counted
ERROR_SCALES = (SCALE_PAPER, SCALE_MEASURED)

# Why a solve stopped (SolveResult.stopped).
STOP_PATHS = "paths"
STOP_TARGET = "target"
STOP_CANCELLED = "cancelled"
STOP_TIME_LIMIT = "time_limit"
