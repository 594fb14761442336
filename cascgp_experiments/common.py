"""Shared pieces of the experiments: model names and labels, grids, the paper's Table I numbers and
the table computation, the shipped nominal URDF and the SARCOS default, JSON and figure writing, thread limits.

Nothing here imports ``jaco_env``, torch or a GP module (only numpy and :mod:`cascgp.io`):
:mod:`cascgp_experiments.plots` imports only this module, :mod:`cascgp_experiments.claims` and
matplotlib, so that figures and tables are regenerated from the JSON alone.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from cascgp.io import atomic_write, json_safe, read_json, write_json  # noqa: F401  (re-exported for the study)

def _jaco_env_dir() -> Path:
    """The installed ``jaco_env`` package's folder, found without importing it (it would import MuJoCo)."""
    spec = importlib.util.find_spec("jaco_env")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError("jaco_env is not installed (pip install cascgp-jaco)")
    return Path(next(iter(spec.submodule_search_locations))).resolve()


#: The nominal URDF of the environments' default arm, shipped as package data of ``jaco_env`` (the same path as
#: ``jaco_env.NOMINAL_URDF``: Kinova's link inertials).
NOMINAL_URDF = _jaco_env_dir() / "assets" / "jaco2_nominal_kinova.urdf"
#: The nominal URDF of the arm with dm_control's link inertials (``jaco_env.nominal_urdf("dm_control")``), the arm
#: of ``sensor_pipeline="ideal"``.
NOMINAL_URDF_DM_CONTROL = _jaco_env_dir() / "assets" / "jaco2_nominal.urdf"

#: Environment variable naming the IAS SARCOS ``.mat`` file used when a command is given no ``--sarcos``.
SARCOS_ENV = "CASCGP_SARCOS"

#: The distribution's name on the package index (``pip install`` it; extras as ``cascgp-jaco[EXTRA]``).
DISTRIBUTION = "cascgp-jaco"


def install_hint(extra: str) -> str:
    """How to install an optional extra: from the wheel the distribution was installed from (README's way), or
    from a source checkout."""
    from cascgp import __version__

    wheel = f"{DISTRIBUTION.replace('-', '_')}-{__version__}-py3-none-any.whl"
    return (f"install the '{extra}' extra: pip install '{wheel}[{extra}]' (the wheel you installed, e.g. in dist/), "
            f"or in a source checkout pip install -e '.[{extra}]'")


def package_versions() -> dict[str, str]:
    """Python's and the installed versions of the packages a result depends on (for a result's provenance); an
    optional one that is not installed (``numba``: the ``fast`` extra's compiled loops) is left out."""
    import importlib.metadata as md
    import platform

    out = {"python": platform.python_version()}
    for p in ("cascgp-jaco", "numpy", "scipy", "torch", "mujoco", "dm-control", "gymnasium", "pin", "numba"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return out


def machine_info() -> dict[str, Any]:
    """The machine a result was computed on (for its provenance): CPU count, platform and processor."""
    import platform

    return {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": _cpu_model()}


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    import platform

    return platform.processor()


def default_sarcos() -> Path | None:
    """The SARCOS file to use when the user names none: ``$CASCGP_SARCOS`` if set, else, in a source checkout that
    has the project's ``shared/`` folder beside it, ``../shared/data/sarcos/ias_sarcos_data.mat``; ``None`` when
    neither exists (an installed package never guesses a path: pass ``--sarcos``)."""
    env = os.environ.get(SARCOS_ENV)
    if env:
        return Path(env)
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file():
        cand = (checkout / ".." / "shared" / "data" / "sarcos" / "ias_sarcos_data.mat").resolve()
        if cand.is_file():
            return cand
    return None


def default_sarcos_source() -> str:
    """Where :func:`default_sarcos`'s path comes from, for messages: ``$CASCGP_SARCOS`` or the checkout's copy."""
    return f"${SARCOS_ENV}" if os.environ.get(SARCOS_ENV) else "the source checkout's SARCOS copy"


#: Name of the parametric baseline in result files (not a cascgp model: RNEA of the nominal URDF).
RBD = "rbd"
#: Paper order of the rows of Table I (derivative based, then derivative free).
STRUCT_ORDER = ("inward", "outward", "standard")


def model_name(param: str, structure: str, df: bool) -> str:
    """cascgp model name, e.g. ``model_name("sp", "inward", True) == "sp-inward-df"``."""
    return f"{param}-{structure}" + ("-df" if df else "")


#: The 12 variants in the paper's table order.
VARIANTS: tuple[str, ...] = tuple(
    model_name(p, s, df) for df in (False, True) for p in ("np", "sp") for s in STRUCT_ORDER)
NP_DB = tuple(model_name("np", s, False) for s in STRUCT_ORDER)


def label(name: str) -> str:
    """Paper-style label: ``np-inward-df`` -> ``NP-Inward-Cascaded-DF``, ``sp-standard`` -> ``SP``."""
    if name == RBD:
        return "RBD"
    parts = name.split("-")
    out = parts[0].upper()
    if parts[1] != "standard":
        out += f"-{parts[1].capitalize()}-Cascaded"
    if parts[-1] == "df":
        out += "-DF"
    return out


def category(name: str) -> str:
    """Table I category of a variant: ``"db-np"``, ``"db-sp"``, ``"df-np"``, ``"df-sp"``."""
    parts = name.split("-")
    return ("df" if parts[-1] == "df" else "db") + "-" + parts[0]


# --------------------------------------------------------------------------- grids
#: Table I intervals (s): the table reports the mean over the grid points inside each.
TABLE_INTERVALS: tuple[tuple[float, float], ...] = ((1.0, 2.0), (4.0, 5.0), (9.0, 10.0))
#: Full grid (s): log-spaced from 1 s to 50 s plus three points in each table interval.
FULL_GRID: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0, 7.0, 9.0, 9.5, 10.0, 14.0, 20.0,
                                30.0, 50.0)
QUICK_GRID: tuple[float, ...] = (1.0, 2.0, 5.0, 10.0)
SMOKE_GRID: tuple[float, ...] = (1.0, 2.0)


def interval_mean(grid: Iterable[float], values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Mean of ``values`` (G, ...) over the grid points ``lo <= T <= hi``; NaN where none."""
    g = np.asarray(list(grid), dtype=float)
    m = (g >= lo - 1e-9) & (g <= hi + 1e-9)
    v = np.asarray(values, dtype=float)
    if not m.any():
        return np.full(v.shape[1:], np.nan)
    return v[m].mean(axis=0)


def median_curves(block: dict[str, Any], scoring: str = "predicted") -> dict[str, Any]:
    """``{model: (G, N)}`` per-grid-point medians over subsets of a curves block; ``scoring="measured"``: the
    cascades scored with the measured neighbour torque (a model without a torque input has one score)."""
    return {m: (v.get("measured", v) if scoring == "measured" else v)["nrmse_median"]
            for m, v in block["models"].items()}


def make_table(grid: list[float], curves: dict[str, list[list[float]]],
               intervals: Iterable[tuple[float, float]] = TABLE_INTERVALS) -> dict[str, Any]:
    """Table I from mean curves: ``{"intervals": [[lo, hi]...], "rows": {model: [[j][k]]},
    "best": {model: [[bool]]}, "near": {model: [[bool]]}}``.

    ``rows[m][j][k]`` is the mean nRMSE of joint ``j`` over the grid points in interval ``k``.
    ``best`` marks the lowest value per (category, joint, interval) among the 12 variants (the
    paper's yellow), ``near`` those within 5 % of it (the paper's light yellow).  The RBD row,
    if present, is reported but never marked.
    """
    intervals = [tuple(map(float, iv)) for iv in intervals]
    rows: dict[str, list[list[float]]] = {}
    for m, c in curves.items():
        arr = np.asarray(c, dtype=float)  # (G, N)
        rows[m] = np.stack([interval_mean(grid, arr, lo, hi) for lo, hi in intervals], axis=1).tolist()
    best = {m: [[False] * len(intervals) for _ in rows[m]] for m in rows}
    near = {m: [[False] * len(intervals) for _ in rows[m]] for m in rows}
    cats: dict[str, list[str]] = {}
    for m in rows:
        if m != RBD:
            cats.setdefault(category(m), []).append(m)
    for members in cats.values():
        n_joints = len(rows[members[0]])
        for j in range(n_joints):
            for k in range(len(intervals)):
                vals = np.array([rows[m][j][k] for m in members], dtype=float)
                if not np.isfinite(vals).any():
                    continue
                lo = np.nanmin(vals)
                for m, v in zip(members, vals):
                    if v == lo:
                        best[m][j][k] = True
                    elif v <= 1.05 * lo:
                        near[m][j][k] = True
    return {"intervals": [list(iv) for iv in intervals], "rows": rows, "best": best, "near": near}


# --------------------------------------------------------------------------- paper numbers
def _rows(s: str) -> list[list[float]]:
    v = [float(x) for x in s.split()]
    return [v[3 * j:3 * j + 3] for j in range(6)]


#: Table I of the paper (nRMSE, joints 1-6 x (1-2 s, 4-5 s, 9-10 s)), copied from the .tex.
PAPER_TABLE: dict[str, list[list[float]]] = {
    "np-inward": _rows(".219 .182 .151 .297 .178 .087 .562 .360 .161 .280 .247 .245 .288 .253 .204 .594 .470 .333"),
    "np-outward": _rows(".229 .206 .172 .421 .293 .125 .565 .367 .213 .271 .210 .173 .330 .310 .303 .331 .286 .255"),
    "np-standard": _rows(".229 .207 .169 .488 .351 .174 .769 .553 .212 .298 .236 .201 .294 .239 .212 .639 .401 .329"),
    "sp-inward": _rows(".198 .171 .147 .085 .068 .058 .129 .143 .123 .258 .210 .172 .191 .191 .176 .590 .449 .335"),
    "sp-outward": _rows(".200 .192 .168 .088 .076 .061 .130 .146 .125 .268 .192 .158 .182 .184 .182 .370 .268 .258"),
    "sp-standard": _rows(".197 .186 .162 .092 .081 .067 .130 .136 .120 .296 .217 .200 .188 .194 .188 .638 .394 .331"),
    "np-inward-df": _rows(".198 .189 .148 .257 .120 .097 .605 .283 .153 .281 .237 .226 .302 .238 .178 .483 .313 .287"),
    "np-outward-df": _rows(".211 .200 .172 .351 .145 .126 .615 .282 .196 .245 .200 .150 .320 .287 .259 .309 .225 .257"),
    "np-standard-df": _rows(".214 .204 .175 .435 .144 .141 .705 .276 .189 .276 .215 .153 .304 .228 .189 .429 .304 .294"),  # noqa: E501 - a table row
    "sp-inward-df": _rows(".186 .182 .147 .076 .064 .067 .125 .124 .122 .259 .177 .134 .194 .196 .177 .471 .314 .294"),
    "sp-outward-df": _rows(".195 .182 .161 .076 .068 .065 .122 .129 .126 .261 .186 .121 .186 .177 .167 .329 .232 .258"),
    "sp-standard-df": _rows(".196 .186 .165 .079 .072 .068 .121 .124 .125 .285 .216 .133 .192 .192 .171 .431 .300 .292"),  # noqa: E501 - a table row
}


# --------------------------------------------------------------------------- I/O
def save_figure(fig: Any, path: str | Path, dpi: int) -> Path:
    """Write a matplotlib figure atomically (:func:`cascgp.io.atomic_write`); the format is the suffix's."""
    path = Path(path)
    return atomic_write(path, lambda f: fig.savefig(f, dpi=dpi, format=path.suffix.lstrip(".")))


def limit_threads(n: int = 1) -> None:
    """Limit torch and BLAS threads (OpenBLAS spinning threads otherwise steal cores from torch)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(n))
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    except ImportError:  # pragma: no cover - threadpoolctl comes with scipy's stack
        pass
    try:
        import torch

        torch.set_num_threads(n)
    except ImportError:  # pragma: no cover
        pass
