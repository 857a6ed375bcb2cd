"""The solve's settings, defined once: names, defaults, ranges and words, for the panel and the command line.

``properties.py`` makes Blender properties of them, ``__main__.py`` command-line options; both
refuse what is out of range the same way. No bpy.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..core.methods import automatic
from ..core.names import SCALE_MEASURED


@dataclass(frozen=True)
class Number:
    name: str            # the property (scene.radiosity.<name>)
    flag: str            # the command-line option
    default: float
    low: float
    high: float | None   # None: no upper bound
    label: str
    description: str
    unit: str = ""
    integer: bool = False
    zero_means: str = ""  # a default that 0 stands for, beside the range (e.g. "automatic")

    def check(self, value):
        """``value``, or ValueError naming the option, its range and the value."""
        if self.zero_means and value == 0:
            return value
        inside = value == value and value >= self.low and (self.high is None or value <= self.high)
        if not inside:
            raise ValueError(f"{self.flag} must be {self.range_text()}; got {value:g}")
        return value

    def number_text(self, value):
        """``value`` as the range says it: whole numbers in full (2147483647, not 2.14748e+09)."""
        return f"{int(value)}" if self.integer else f"{value:g}"

    def range_text(self):
        unit = f" {self.unit}" if self.unit else ""
        if self.high is None:
            text = f"at least {self.number_text(self.low)}{unit}"
        else:
            text = f"between {self.number_text(self.low)} and {self.number_text(self.high)}{unit}"
        return f"0 ({self.zero_means}) or {text}" if self.zero_means else text


@dataclass(frozen=True)
class Choice:
    name: str
    flag: str
    default: str
    items: tuple  # (identifier, label, description)
    label: str
    description: str = ""

    def check(self, value):
        ids = [i for i, _, _ in self.items]
        for i in ids:
            if value.lower() == i.lower():
                return i
        raise ValueError(f"{self.flag} must be one of {', '.join(ids)}; got {value!r}")

    def item_label(self, value):
        """The label of item ``value`` (as the panel shows it)."""
        return next((label for i, label, _ in self.items if i == value), value)


@dataclass(frozen=True)
class Flag:
    name: str
    flag: str  # --flag / --no-flag
    default: bool
    label: str
    description: str

    def check(self, value):
        return bool(value)


@dataclass(frozen=True)
class Text:
    name: str
    flag: str
    default: str
    label: str
    description: str

    def check(self, value):
        return str(value).strip()


class ClusterAddress(Text):
    def check(self, value):
        """'' (this machine), or a scheduler address in a form Dask's client takes (tcp://, tls://),
        or ValueError saying which: checked without connecting."""
        text = super().check(value)
        if not text:
            return text
        from ..core.distributed.cluster_connect import cluster_address

        return cluster_address(text)


METHOD = Choice("method", "--method", "auto", (
    ("auto", "Automatic", "The two-way iteration where each patch gets enough rays for it to pay (scenes of up "
     f"to {automatic.patches_text()} patches, at error targets that need some rays a patch), else the paper's random "
     "walks, which need fewer rays at a few a patch and where the light lands on few patches (a narrow spot). "
     "The estimate says which"),
    ("walk", "Random walks (paper)", "The paper's shooting random walks, with its estimators: their predicted path "
     "counts and relative efficiency hold for them"),
    ("two_way", "Two-way iteration", "Beyond the paper: the direct light gathered by shadow rays, then the light "
     "passed on generation by generation, every ray used both ways (shooting and gathering) about a control "
     "variate. Faster to the same error in the rooms measured, of 600 to 500,000 patches; slower where a "
     "large emitter lights most of the scene directly. No formula predicts its error, which is measured as it "
     "runs. The estimator, sampling and direct light settings are the walks'"),
), "Method", "How the light is computed: the paper's random walks, the two-way iteration, or Automatic's choice")
ESTIMATOR = Choice("estimator", "--estimator", "finite", (
    ("finite", "Finite (Phi_T)", "The paper's finite estimator: constant power, a path survives a "
     "hit with the patch's reflectivity"),
    ("biased_infinite", "Biased infinite", "The paper's biased infinite estimator: power times the "
     "reflectivity at every hit, cut when the accumulated reflectivity falls below the threshold t"),
), "Estimator", "The random walks' estimator (the paper's two); the two-way iteration has its own")
THRESHOLD = Number("threshold", "--threshold", 1e-3, 1e-6, 0.5, "Threshold t",
                   "Biased infinite estimator: a path ends when the product of reflectivities along it is below t")
TARGET_ERROR = Number("target_error", "--error", 5.0, 0.05, 100.0, "Error target",
                      "Relative RMS error wanted, as a percentage of the mean light the selection reflects. It is "
                      "the Monte Carlo noise of the patch values, both measured as the run goes; it does not include "
                      "how a flat colour per patch differs from the continuous light across it (smaller patches "
                      "shrink that), nor, with the random exit point, the patch values' own discretization error",
                      unit="%")
PATCH_SIZE = Number("patch_size", "--patch-size", 0.0, 1e-4, None, "Patch size",
                    "Largest patch edge: faces longer than this are subdivided (0: automatic, 1/20 of the "
                    "selection's largest extent)", zero_means="automatic")
EXIT_POINT = Choice("exit_point", "--exit-point", "hit", (
    ("hit", "Hit point", "The next ray leaves from the point that was hit: each patch converges to the continuous "
     "light averaged over it, what a render shows; as close to Cycles or closer at equal time for every method measured"),
    ("random", "Random (paper)", "The next ray leaves from a random point of the hit patch (the paper's discrete "
     "method): each patch converges to the radiosity system of flat patches, which differs from the continuous "
     "light by a discretization error the error estimate does not show (up to about 2% a patch in the scenes "
     "measured, less on smaller patches)"),
), "Exit point", "Where a ray leaves the patch it hit: the hit point converges to the continuous light "
   "averaged over each patch, the random point (the paper's) to the flat-patch system")
SAMPLING = Choice("sampling", "--sampling", "independent", (
    ("independent", "Independent (paper)", "Sources and first rays drawn independently, as in the paper: "
     "the predicted path counts are derived for this"),
    ("stratified", "Stratified", "Paths allotted to sources in proportion to power and a randomly shifted "
     "low-discrepancy first ray: same expected result, usually less noise for the same time"),
), "Sampling", "How the random walks draw their sources and first rays")
DIRECT_LIGHT = Choice("direct_light", "--direct-light", "shot", (
    ("shot", "Shot (paper)", "The paper's walk: paths from the sources carry the direct light too; its predicted "
     "path counts and the estimators' relative efficiency hold for it"),
    ("gathered", "Gathered", "Each patch gathers its direct light by shadow rays to the sources, and the walks carry "
     "only reflected light: no formula predicts its error, which is measured as it runs. Lamps without shadow or "
     "with soft falloff are always gathered"),
), "Direct light", "How the random walks compute the direct light. The two-way iteration, which Automatic picks where "
   "each patch gets enough rays (most rooms, the main job's box too), always gathers it, and so do lamps without "
   "shadow or with soft falloff (Blender's default): there this setting changes nothing")
STOP_RULE = Choice("stop_rule", "--stop-rule", "measured", (
    ("measured", "Measured error", "Run until the run's own estimate of its error (from independent batches) "
     "meets the target: what you ask for is what you get. The paper's predicted path count is the plan"),
    ("predicted", "Predicted paths", "Run the number of paths the paper's formula (2)/(3) predicts for the "
     "target (a heuristic: the error reached can be above the target)"),
), "Stop at", "When a run stops: when its measured error meets the target, or after the paper's predicted paths")
# The error target is relative to the run's own mean reflected radiosity, not the paper's
# closed-scene b_ave: where light leaves the selection (a window, a room open to the sky) b_ave
# counts it as if it stayed, and the noise in the room came out up to 3x the target (docs/errors.md).
ERROR_SCALE = SCALE_MEASURED
# Both makes the smooth light up to this many patches (at a million, smoothing took as long as the
# solve and 0.8 GB more: the command line's peak went from 916 to 1,706 MiB without its preview).
SMOOTH_MAX_PATCHES = 300_000

OUTPUT = Choice("output", "--colours", "TEXTURED", (
    ("TEXTURED", "Textured", "Each material's own surface colour (its image textures and colour attributes, through "
     "the result's copy of the UV maps) times the smooth light arriving ('Radiosity Light'), plus its emission, in a "
     "copy of the material; also Both's attributes. Above "
     f"{SMOOTH_MAX_PATCHES:,} patches, each patch's light, flat"),
    ("FACE", "Face colours", "Flat colour per patch on the CORNER domain (the paper's view)"),
    ("VERTEX", "Smooth colours", "Smooth light on every face corner: joined across objects that touch, kept apart "
     "at creases, each patch's light kept, tile noise filtered within its measured error"),
    ("BOTH", "Both", f"Smooth colours as 'Radiosity' (shown), the flat per-patch colours as 'Radiosity Patches'; "
     f"above {SMOOTH_MAX_PATCHES:,} patches the flat ones alone, as 'Radiosity'"),
), "Colours", "What the results show: the materials' own textures times the light, or the light's colours alone")
PER_SOURCE = Choice("per_source", "--per-light", "AUTO", (
    ("AUTO", "Automatic", "On where the scene has 2 to 8 sources (lamps, the world, emissive materials, or "
     "Blender's light groups) and patches x sources stay within a million: the walks' solves then take about "
     "1.1-1.3x the time; more sources cost more (up to 2.8x with the two-way iteration at 17)"),
    ("ON", "On", "Keep every source's own result, from the same rays, in the .blend, so that Relight recombines "
     "them with new strengths and colours without tracing a ray; refused beyond patches x sources of 8 million"),
    ("OFF", "Off", "The total only: the fastest solve; a changed lamp needs a new solve"),
), "Per-light results", "Keep each light's own result so that turning a lamp's strength or colour relights at once")
LIVE_LAMPS = Flag("live_lamps", "--live-lamps", True, "Live lamps",
                  "Textured: the lamps', suns', emitting materials' and the world's own light on the results is "
                  "drawn by Cycles, each pixel's (sharp hot spots and shadows, the material's highlights), and "
                  "the solve gives the rest ('Radiosity Bounced Light'). On (default): right in Cycles' render of "
                  "the scene at any bounces, as the preview and the saved file draw it; EEVEE and Material Preview "
                  "show all of the light from the solve ('Radiosity Light'); off: all of the light from the solve, "
                  "the same in any view (Material Preview's studio light too)")
DISPLAY_CELLS = Flag("display_cells", "--display-cells", True, "Display cells",
                     "Smooth colours: the display's own smaller cells inside a patch where the direct light changes "
                     "(a lamp's hot spot, a spot's cone, a shadow's edge), the light taken at their corners; the solve "
                     "and each patch's mean stay as they are. On (default): the light's shape in EEVEE, Material "
                     "Preview, Solid view and exporters; off: one polygon per patch")
# --- Detail (adaptive patches) ---
DETAIL = Choice("detail", "--detail", "OFF", (
    ("OFF", "Off", "Every patch the patch size: the same grid everywhere"),
    ("LOW", "Low", "Patches where the direct light changes split once (at most 1.5x the patches)"),
    ("MEDIUM", "Medium", "Split up to twice, down to a quarter of the patch size, where the direct light changes "
     "by a quarter (at most 2.5x the patches)"),
    ("HIGH", "High", "Split up to three times, down to an eighth of the patch size, where the direct light changes "
     "by an eighth (at most 4x the patches)"),
), "Detail", "Smaller patches where the direct light changes (a lamp's hot spot, shadow edges, a spot's cone, "
   "sun through a window), found by shadow rays before the solve; large patches where it is flat")

SEED = Number("seed", "--seed", 0, 0, 2**31 - 1, "Seed", "Random seed (same seed, same result)", integer=True)
TIME_LIMIT = Number("time_limit", "--time-limit", 0.0, 0.0, None, "Time limit",
                    "The whole run in this many seconds (0: no limit): meshing, the solve and the colours; the solve "
                    "stops in time for the colours and its paths done so far are kept", unit="s")
THREADS = Number("threads", "--threads", 0, 0, 64, "Threads",
                 "Threads for the ray tracing (0: automatic). Same seed and threads give the same result",
                 integer=True)

SCENE_OBJECTS = Flag("use_scene_objects", "--scene-objects", True, "Rest of the scene",
                     "The other visible objects block and reflect light (meshed coarser, no results written), as "
                     "they do in a render; off: only the selection takes part")

CLAMP = Flag("clamp_reflectivity", "--clamp-bright-colours", False, "Clamp bright colours",
             "Use 0.99 for base colours above it (white is 1.0) instead of refusing colours of 1 or more, which "
             "would never let a path end in a closed room; reported as a warning")

LIGHT_OUTPUT = Flag("light_output", "--light-output", False, "Light only",
                    "Also write the light arriving at each patch, without the surface's colour ('Radiosity Light': "
                    "Cycles' Diffuse bake without Color), to multiply with textures in a material (Textured "
                    "writes it smooth and does so)")
INDIRECT_OUTPUT = Flag("indirect_output", "--indirect-output", False, "Indirect light",
                       "Also write the light arriving after at least one bounce, without the surface's colour "
                       "('Radiosity Indirect')")

CLUSTER = ClusterAddress("cluster", "--cluster", "", "Cluster",
                         "A Dask scheduler's address, tcp://host:port or tls://host:port, to run the walks on its "
                         "workers; empty: this machine. Same seed, bitwise the same result. Trust the cluster as "
                         "you trust this machine: Dask's messages can run code on either side. Across a network "
                         "use tls:// with the cluster's certificates, from Dask's configuration "
                         "(distributed.comm.tls.ca-file, .client.cert, .client.key) or its environment "
                         "(DASK_DISTRIBUTED__COMM__TLS__CA_FILE, __CLIENT__CERT, __CLIENT__KEY)")

SETTINGS = (METHOD, ESTIMATOR, THRESHOLD, TARGET_ERROR, PATCH_SIZE, DETAIL, EXIT_POINT, SAMPLING, DIRECT_LIGHT,
            STOP_RULE, OUTPUT, LIVE_LAMPS, DISPLAY_CELLS, PER_SOURCE, SEED,
            TIME_LIMIT, THREADS, SCENE_OBJECTS, CLAMP, LIGHT_OUTPUT, INDIRECT_OUTPUT, CLUSTER)

# Patch size 0: the selection's largest extent over this.
AUTOMATIC_PATCH_DIVISIONS = 20
