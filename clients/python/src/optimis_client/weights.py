"""Evaluate a portable weights artifact (``optimis weights``, format ``optimis-weights``, version 1)
in pure Python and numpy: the weight of a merge by technique m on a join path, from the artifact
alone and what a renderer knows of the path.

This is a port of the Rust reference evaluator (``src/sim/weights/function.rs``) and of its
model-scene helper (``src/sim/weights/densities.rs``), with the same arithmetic in the same order,
so that it reproduces the engine's weights to rounding (the test vectors written by
``optimis weights --vectors`` check it: :func:`check_vectors`).

The weight of a merge by technique m (0: plane 1, the pixel; 1: plane 2; 2: plane 3) is::

    w_m = T_m(cell(r2, r3, phi)) + sum_h beta_h * w_h,m(path)

with ``T`` the artifact's table (0 where it has none) and ``w_h`` each stacked heuristic's weight,
defined by its ``formula`` (docs/model.md §9).

**Frame and units** (docs/model.md §1). The model scene is three planes orthogonal to z: plane 1
at z = 0 with the camera's pixel at its origin, plane 2 at z = L2 and plane 3 at z = L2 + L3. A
position on a plane is 2-D, ``(x, y)`` in that plane's coordinates (the same x and y axes on every
plane). Lengths are in the scene's own unit (the one of the job that made the artifact: L2, L3, R
and the cell edges share it), angles in radians, and densities are per unit area of that unit
(area measure). The cell coordinates of a join path (0, x2, x3) are r2 = |x2|, r3 = |x3| and φ, the
angle between the vectors x2 and x3, in [0, π].

**Vertex densities.** The heuristics read the sampling densities of the join path's vertices, each
per unit area:

* ``camera_x2`` — p_c(x2), the camera sub-path's density of its plane-2 vertex;
* ``camera_x3`` — p_c(x3 | x2), its density of the plane-3 vertex given x2;
* ``light_start`` — p_l(x3l), the light path's density of its own start x3l (I(x3l)/Φ);
* ``light_x2`` — p_l(x2 | x3), the light sub-path's density of its plane-2 vertex;
* ``light_x1`` — p_l(x1 | x2, x3), its density of the pixel's vertex on plane 1.

The techniques' path densities are their products, p0 = light_x2·light_x1,
p1 = camera_x2·light_x2, p2 = camera_x2·camera_x3 (the light's start density, common to all three,
cancels; only the correlation-aware counts read it). For the model scene itself,
:func:`model_path` computes all of them from the path's vertices. A renderer of *another* scene
passes its own: the area densities with which its own camera and light sub-path samplers generate
the corresponding vertices of the path (docs/model.md §9: the product of the camera sub-path's
vertex densities up to the merge vertex and the light sub-path's down to it), and its own r2, r3, φ
only if it uses the artifact's table, which is defined on the model scene's cells.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

#: The artifact's ``format``.
WEIGHTS_FORMAT = "optimis-weights"
#: The artifact's ``version``: another is refused.
WEIGHTS_VERSION = 1
#: Most cells a table may have.
MAX_TABLE_CELLS = 256
#: Most stacked heuristics.
MAX_HEURISTICS = 16
#: Most illumination rings.
MAX_RINGS = 64

#: The header of the test-vector CSV of ``optimis weights --vectors``.
VECTOR_COLUMNS = ("technique", "x2_x", "x2_y", "x3_x", "x3_y", "x3l_x", "x3l_y", "weight")

#: The artifact's kinds.
KINDS = ("table", "heuristic", "stack")

#: Each formula's parameters (besides ``kind``), in the artifact's spelling.
FORMULAS: Dict[str, Tuple[str, ...]] = {
    "one_technique": ("technique",),
    "switch": ("radius",),
    "balance": (),
    "power": ("exponent",),
    "correlation_aware": ("area", "light_paths", "camera_paths"),
}

ArrayLike = Union[float, int, Sequence[float], np.ndarray]
Source = Union[str, "os.PathLike[str]", Mapping[str, Any]]


# ---------------------------------------------------------------------------------------------
# The artifact, checked


@dataclass(frozen=True)
class Ring:
    """One ring of the light's radial profile on plane 3: radii [inner, outer) (scene units), its
    unnormalised level."""

    inner: float
    outer: float
    level: float


@dataclass(frozen=True)
class Scene:
    """The model scene an artifact's coordinates and densities refer to (docs/model.md §1–§4):
    plane 1 (the pixel's, at its origin) at z = 0, plane 2 at z = ``l2``, plane 3 at
    z = ``l2 + l3``; lengths in the scene's unit, ``beta_rad`` (the lobe's width) in radians. The
    light's start density is ``level / flux`` inside a ring, 0 outside every ring."""

    l2: float
    l3: float
    beta_rad: float
    merge_radius: float
    light_paths: float
    camera_paths: float
    rings: Tuple[Ring, ...]
    flux: float


@dataclass(frozen=True)
class CellAxes:
    """The table's axes: edges of r2 and of r3 from 0 (bin k is [e_k, e_k+1), the last to ∞) and
    ``phi_bins`` equal bins of φ over [0, π] (the last includes π)."""

    r2_edges: Tuple[float, ...]
    r3_edges: Tuple[float, ...]
    phi_bins: int

    @property
    def cells(self) -> int:
        """How many cells the axes make."""
        return len(self.r2_edges) * len(self.r3_edges) * self.phi_bins


@dataclass(frozen=True)
class Heuristic:
    """One per-path heuristic of the function: its name in results, its coefficient β, its
    formula (``kind`` and parameters, as in the artifact) and which techniques it weighs."""

    name: str
    beta: float
    formula: Mapping[str, Any]
    techniques: Tuple[bool, bool, bool]

    @property
    def kind(self) -> str:
        """The formula's kind (``balance``, ``correlation_aware``…)."""
        return str(self.formula["kind"])


def _where(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _object(value: Any, path: str, required: Sequence[str], optional: Sequence[str] = ()) -> Mapping[str, Any]:
    """`value` as a JSON object with the `required` keys and no key beyond `optional` (the Rust
    reader denies unknown fields)."""
    if not isinstance(value, Mapping):
        raise ValueError(f"weights artifact: {path or 'the artifact'} must be a JSON object, not {type(value).__name__}")
    for key in required:
        if key not in value:
            raise ValueError(f"weights artifact: {_where(path, key)} is missing")
    for key in value:
        if key not in required and key not in optional:
            raise ValueError(f"weights artifact: unknown field {_where(path, str(key))!r}")
    return value


def _number(value: Any, path: str) -> float:
    """A finite JSON number (integers allowed, booleans not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"weights artifact: {path} must be a number, not {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"weights artifact: {path} must be finite, not {value!r}")
    return x


def _integer(value: Any, path: str, upper: Optional[int] = None) -> int:
    """A non-negative JSON integer (at most `upper`)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0 or (upper is not None and value > upper):
        bound = f" ≤ {upper}" if upper is not None else ""
        raise ValueError(f"weights artifact: {path} must be an integer ≥ 0{bound}, not {value!r}")
    return int(value)


def _list(value: Any, path: str) -> List[Any]:
    if not isinstance(value, list):
        raise ValueError(f"weights artifact: {path} must be a JSON array, not {type(value).__name__}")
    return value


def _scene(value: Any) -> Scene:
    keys = ("l2", "l3", "beta_rad", "merge_radius", "light_paths", "camera_paths", "rings", "flux")
    doc = _object(value, "scene", keys)
    rings = _list(doc["rings"], "scene.rings")
    if len(rings) > MAX_RINGS:
        raise ValueError(f"weights artifact: too many rings ({len(rings)}, at most {MAX_RINGS})")
    parsed = []
    for i, ring in enumerate(rings):
        where = f"scene.rings[{i}]"
        r = _object(ring, where, ("inner", "outer", "level"))
        parsed.append(Ring(*(_number(r[k], f"{where}.{k}") for k in ("inner", "outer", "level"))))
    numbers = {k: _number(doc[k], f"scene.{k}") for k in keys if k != "rings"}
    return Scene(rings=tuple(parsed), **numbers)


def _axes(value: Any) -> CellAxes:
    doc = _object(value, "cells", ("r2_edges", "r3_edges", "phi_bins"))
    edges = {}
    for key in ("r2_edges", "r3_edges"):
        e = [_number(x, f"cells.{key}[{i}]") for i, x in enumerate(_list(doc[key], f"cells.{key}"))]
        if not e or e[0] != 0.0 or any(b <= a for a, b in zip(e, e[1:])):
            raise ValueError(f"weights artifact: cells.{key} must start at 0 and increase, not {e}")
        edges[key] = tuple(e)
    phi_bins = _integer(doc["phi_bins"], "cells.phi_bins", 2**32 - 1)
    if phi_bins == 0:
        raise ValueError("weights artifact: cells.phi_bins must be ≥ 1")
    return CellAxes(r2_edges=edges["r2_edges"], r3_edges=edges["r3_edges"], phi_bins=phi_bins)


def _table(value: Any, axes: CellAxes) -> np.ndarray:
    """The table by cell index (i2·n3 + i3)·nφ + iφ, shape (cells, 3): every cell exactly once."""
    entries = _list(value, "table")
    n2, n3, nphi = len(axes.r2_edges), len(axes.r3_edges), axes.phi_bins
    cells = axes.cells
    if cells > MAX_TABLE_CELLS:
        raise ValueError(
            f"weights artifact: too many cells: the axes make {cells} ({n2} × {n3} × {nphi}), at most {MAX_TABLE_CELLS}"
        )
    if len(entries) > cells:
        raise ValueError(f"weights artifact: too many cells: the table has {len(entries)} cells, its axes {cells}")
    table = np.zeros((cells, 3))
    seen = np.zeros(cells, dtype=bool)
    for n, entry in enumerate(entries):
        where = f"table[{n}]"
        c = _object(entry, where, ("r2", "r3", "phi", "w"))
        i2, i3, iphi = (_integer(c[k], f"{where}.{k}") for k in ("r2", "r3", "phi"))
        w = _list(c["w"], f"{where}.w")
        if len(w) != 3:
            raise ValueError(f"weights artifact: {where}.w must hold 3 weights, not {len(w)}")
        weights = [_number(x, f"{where}.w[{k}]") for k, x in enumerate(w)]
        if i2 >= n2 or i3 >= n3 or iphi >= nphi:
            raise ValueError(
                f"weights artifact: cell ({i2}, {i3}, {iphi}) is outside the axes ({n2} × {n3} × {nphi} bins)"
            )
        index = (i2 * n3 + i3) * nphi + iphi
        if seen[index]:
            raise ValueError(f"weights artifact: cell ({i2}, {i3}, {iphi}) is listed twice")
        seen[index] = True
        table[index] = weights
    if not seen.all():
        missing = int(np.flatnonzero(~seen)[0])
        i2, rest = divmod(missing, n3 * nphi)
        i3, iphi = divmod(rest, nphi)
        raise ValueError(
            f"weights artifact: cell ({i2}, {i3}, {iphi}) is missing "
            f"(the table has {len(entries)} cells, its axes {cells})"
        )
    return table


def _heuristic(value: Any, n: int) -> Heuristic:
    where = f"heuristics[{n}]"
    doc = _object(value, where, ("name", "beta", "formula", "techniques"))
    if not isinstance(doc["name"], str):
        raise ValueError(f"weights artifact: {where}.name must be a string")
    beta = _number(doc["beta"], f"{where}.beta")
    f = doc["formula"]
    if not isinstance(f, Mapping) or "kind" not in f:
        raise ValueError(f"weights artifact: {where}.formula must be an object with a kind")
    kind = f["kind"]
    if kind not in FORMULAS:
        raise ValueError(f"weights artifact: {where}.formula.kind {kind!r} is not one of {', '.join(FORMULAS)}")
    params = FORMULAS[kind]
    _object(f, f"{where}.formula", ("kind",) + params)
    formula: Dict[str, Any] = {"kind": kind}
    for p in params:
        at = f"{where}.formula.{p}"
        formula[p] = _integer(f[p], at) if p == "technique" else _number(f[p], at)
    mask = _list(doc["techniques"], f"{where}.techniques")
    if len(mask) != 3 or not all(isinstance(b, bool) for b in mask):
        raise ValueError(f"weights artifact: {where}.techniques must be 3 booleans, not {mask!r}")
    return Heuristic(name=doc["name"], beta=beta, formula=formula, techniques=(mask[0], mask[1], mask[2]))


# ---------------------------------------------------------------------------------------------
# The evaluator


def _array(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _bin(edges: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The last k with edges[k] ≤ r (0 for r < 0 or NaN)."""
    k = np.searchsorted(edges, r, side="right") - 1
    k = np.where(np.isnan(r), 0, k)
    return np.maximum(k, 0)


def cell_index(axes: CellAxes, r2: ArrayLike, r3: ArrayLike, phi: ArrayLike) -> np.ndarray:
    """The cell index (i2·n3 + i3)·nφ + iφ of (r2, r3, φ) on `axes` (r2, r3 in scene units, φ in
    radians): a value on an edge belongs to the bin above it, φ's bin is ⌊φ/π·nφ⌋ capped at the
    last (0 when nφ = 1, and for φ < 0 or NaN)."""
    r2, r3, phi = np.broadcast_arrays(_array(r2), _array(r3), _array(phi))
    nphi = axes.phi_bins
    if nphi == 1:
        iphi = np.zeros(phi.shape, dtype=np.int64)
    else:
        with np.errstate(invalid="ignore"):
            t = phi / math.pi * nphi
            # Rust's `as usize`: truncation, NaN and negatives to 0, saturating above.
            t = np.where(np.isnan(t), 0.0, np.clip(t, 0.0, nphi - 1))
        iphi = np.floor(t).astype(np.int64)
    i2 = _bin(np.asarray(axes.r2_edges), r2)
    i3 = _bin(np.asarray(axes.r3_edges), r3)
    return np.asarray((i2 * len(axes.r3_edges) + i3) * nphi + iphi)


def _balance(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Balance weights (p_m / Σ p), shape (..., 3)."""
    total = p0 + p1 + p2
    return np.stack([p0 / total, p1 / total, p2 / total], axis=-1)


def _hit(area: float, p: np.ndarray) -> np.ndarray:
    """min(1, A·p), with Rust's f64::min (NaN gives 1)."""
    return np.fmin(area * p, 1.0)


def _heuristic_weights(h: Heuristic, inputs: Mapping[str, np.ndarray]) -> np.ndarray:
    """Heuristic `h`'s weights of all three techniques, shape (..., 3) (0 where `h` does not weigh
    the technique)."""
    r3 = inputs["r3"]
    kind = h.kind
    shape = r3.shape
    if kind == "one_technique":
        out = np.zeros(shape + (3,))
        t = h.formula["technique"]
        if t < 3:
            out[..., t] = 1.0
    elif kind == "switch":
        # NaN r3 is not ≤ radius: technique 2.
        one = r3 <= h.formula["radius"]
        out = np.stack([np.zeros(shape), np.where(one, 1.0, 0.0), np.where(one, 0.0, 1.0)], axis=-1)
    else:
        cx2, cx3 = inputs["camera_x2"], inputs["camera_x3"]
        lx2, lx1 = inputs["light_x2"], inputs["light_x1"]
        zero = np.zeros(shape)
        p = [lx2 * lx1, cx2 * lx2, cx2 * cx3]
        p = [p[k] if h.techniques[k] else zero for k in range(3)]
        if kind == "balance":
            out = _balance(*p)
        elif kind == "power":
            e = h.formula["exponent"]
            out = _balance(*(np.power(x, e) for x in p))
        else:  # correlation_aware
            area = h.formula["area"]
            nf, nb = h.formula["light_paths"], h.formula["camera_paths"]
            camera_x2 = _hit(area, cx2)
            light_x3 = _hit(area, inputs["light_start"])
            light_x2 = light_x3 * _hit(area, lx2)
            camera = [np.ones(shape), camera_x2, camera_x2 * _hit(area, cx3)]
            light = [light_x2 * _hit(area, lx1), light_x2, light_x3]
            n = []
            for pc, pl in zip(camera, light):
                own = 1.0 - pc * pl
                shared = own + (nb - 1.0) * pc * (1.0 - pl) + (nf - 1.0) * pl * (1.0 - pc)
                # shared = 0 only if P_c = P_l = 1: every pair is the same sample, n = 1.
                n.append(np.where(shared > 0.0, own / shared, 1.0 / (nf * nb)))
            out = _balance(n[0] * p[0], n[1] * p[1], n[2] * p[2])
    for k in range(3):
        if not h.techniques[k]:
            out[..., k] = 0.0
    return out


class WeightFunction:
    """A checked weights artifact, ready to evaluate.

    Make one with :meth:`load` (a path, a JSON string or a parsed dict). The artifact is checked
    as the Rust reader does — format and version, every field of the schema and no other, a
    complete table (every cell exactly once) on valid axes, bounded sizes — and a
    :class:`ValueError` names what is wrong.
    """

    def __init__(self, artifact: Mapping[str, Any]) -> None:
        """Check `artifact` (a parsed ``optimis-weights`` document) and prepare it."""
        if not isinstance(artifact, Mapping):
            raise ValueError(f"weights artifact: must be a JSON object, not {type(artifact).__name__}")
        fmt, version = artifact.get("format"), artifact.get("version")
        if fmt != WEIGHTS_FORMAT or isinstance(version, bool) or version != WEIGHTS_VERSION or not isinstance(version, int):
            raise ValueError(
                f"weights artifact: format {fmt!r} version {version!r}, "
                f"expected format {WEIGHTS_FORMAT!r} version {WEIGHTS_VERSION}"
            )
        doc = _object(
            artifact,
            "",
            ("format", "version", "strategy", "recommended", "kind", "scene", "provenance"),
            # The signature is the server's, over the artifact's canonical bytes (`optimis
            # evaluate --weights` and the server verify it); it does not change the weights.
            ("cells", "table", "heuristics", "signature"),
        )
        if not isinstance(doc["strategy"], str):
            raise ValueError("weights artifact: strategy must be a string")
        if not isinstance(doc["recommended"], bool):
            raise ValueError("weights artifact: recommended must be true or false")
        kind = doc["kind"]
        if kind not in KINDS:
            raise ValueError(f"weights artifact: kind {kind!r} is not one of {', '.join(KINDS)}")
        self.scene: Scene = _scene(doc["scene"])
        heuristics = _list(doc.get("heuristics", []), "heuristics")
        if len(heuristics) > MAX_HEURISTICS:
            raise ValueError(f"weights artifact: too many heuristics ({len(heuristics)}, at most {MAX_HEURISTICS})")
        self.heuristics: Tuple[Heuristic, ...] = tuple(_heuristic(h, n) for n, h in enumerate(heuristics))
        table = _list(doc.get("table", []), "table")
        cells = doc.get("cells")
        self.cells: Optional[CellAxes] = None
        self.table: Optional[np.ndarray] = None
        if cells is None:
            if table:
                raise ValueError("weights artifact: a table without cells (cells is null)")
        else:
            self.cells = _axes(cells)
            self.table = _table(table, self.cells)
        if kind == "heuristic" and (len(self.heuristics) != 1 or self.table is not None):
            raise ValueError("weights artifact: a heuristic artifact holds one heuristic and no table")
        if kind != "heuristic" and self.table is None:
            raise ValueError(f"weights artifact: a {kind} artifact needs its table (cells and table)")
        prov = _object(
            doc["provenance"],
            "provenance",
            ("fingerprint", "iterations", "coverage", "generator"),
            ("lambda", "rms_percent", "rms_percent_stderr", "job_id"),
        )
        self.kind: str = kind
        self.strategy: str = doc["strategy"]
        self.recommended: bool = doc["recommended"]
        self.provenance: Mapping[str, Any] = prov
        self.artifact: Mapping[str, Any] = artifact

    @classmethod
    def load(cls, source: Source) -> "WeightFunction":
        """An artifact from a path (``str`` or path-like) of its JSON file, a JSON string (a
        ``str`` starting with ``{``) or a parsed dict, checked (:class:`ValueError` if it is not a
        valid version-1 artifact)."""
        if isinstance(source, str) and source.lstrip().startswith("{"):
            text = source
        elif isinstance(source, (str, os.PathLike)):
            text = Path(source).read_text(encoding="utf-8")
        else:
            return cls(source)
        try:
            doc = json.loads(text, parse_constant=_refuse_constant)
        except json.JSONDecodeError as e:
            raise ValueError(f"weights artifact: not JSON: {e}") from e
        return cls(doc)

    @property
    def beta_sum(self) -> float:
        """Σ|β_h| over the stacked heuristics (the scale of :func:`check_vectors`' error)."""
        return float(sum(abs(h.beta) for h in self.heuristics))

    def weights(
        self,
        r2: ArrayLike,
        r3: ArrayLike,
        phi: ArrayLike,
        camera_x2: ArrayLike,
        camera_x3: ArrayLike,
        light_start: ArrayLike,
        light_x2: ArrayLike,
        light_x1: ArrayLike,
    ) -> np.ndarray:
        """The weights (w0, w1, w2) of the merges by each technique on the join paths given
        (arrays broadcast together), shape (..., 3). Arguments as for :meth:`weight`."""
        names = ("r2", "r3", "phi", "camera_x2", "camera_x3", "light_start", "light_x2", "light_x1")
        arrays = np.broadcast_arrays(*(_array(x) for x in (r2, r3, phi, camera_x2, camera_x3, light_start, light_x2, light_x1)))
        inputs = dict(zip(names, arrays))
        shape = arrays[0].shape
        if self.table is not None and self.cells is not None:
            table = self.table[cell_index(self.cells, inputs["r2"], inputs["r3"], inputs["phi"])]
        else:
            table = np.zeros(shape + (3,))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            stacked = np.zeros(shape + (3,))
            for h in self.heuristics:
                stacked = stacked + h.beta * _heuristic_weights(h, inputs)
        return np.asarray(table + stacked)

    def weight(
        self,
        technique: Union[int, ArrayLike],
        r2: ArrayLike,
        r3: ArrayLike,
        phi: ArrayLike,
        camera_x2: ArrayLike,
        camera_x3: ArrayLike,
        light_start: ArrayLike,
        light_x2: ArrayLike,
        light_x1: ArrayLike,
    ) -> np.ndarray:
        """The weight of a merge by `technique` (0: plane 1, the pixel; 1: plane 2; 2: plane 3; an
        int or an integer array) on the join path (0, x2, x3), vectorised: every argument may be an
        array, and they broadcast together.

        * `r2` = |x2| and `r3` = |x3|: the radii (scene units) of the join path's plane-2 and
          plane-3 vertices from the axis through the pixel (x3 is the camera's x3c for a plane-3
          merge, the light's otherwise); `phi`: the angle between x2 and x3 in [0, π], radians.
          Only the table reads them (and ``switch`` reads r3).
        * the vertex densities, per unit area (module doc): `camera_x2` = p_c(x2),
          `camera_x3` = p_c(x3 | x2), `light_start` = p_l(x3l) of the light path's own start,
          `light_x2` = p_l(x2 | x3), `light_x1` = p_l(x1 | x2, x3). For the model scene,
          :func:`model_path` computes them; a renderer of another scene passes its own samplers'
          densities of the corresponding vertices.
        """
        t = np.asarray(technique)
        if not np.issubdtype(t.dtype, np.integer) or (t.size and (t.min() < 0 or t.max() > 2)):
            raise ValueError(f"technique must be 0, 1 or 2 (an integer or integer array), not {technique!r}")
        all_three = self.weights(r2, r3, phi, camera_x2, camera_x3, light_start, light_x2, light_x1)
        t, all_three = _broadcast_technique(t, all_three)
        return np.asarray(np.take_along_axis(all_three, t[..., None], axis=-1)[..., 0])

    def weight_of(self, technique: Union[int, ArrayLike], path: "ModelPath") -> np.ndarray:
        """:meth:`weight` on the join paths of :func:`model_path`."""
        return self.weight(technique, **path.inputs())

    def __repr__(self) -> str:
        cells = f", {self.cells.cells} cells" if self.cells else ""
        names = ", ".join(f"{h.name} β={h.beta:g}" for h in self.heuristics)
        return f"WeightFunction({self.strategy!r}, kind={self.kind!r}{cells}, heuristics=[{names}])"


def _refuse_constant(name: str) -> float:
    raise ValueError(f"weights artifact: {name} is not a JSON number")


def _broadcast_technique(t: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    shape = np.broadcast_shapes(t.shape, w.shape[:-1])
    return np.broadcast_to(t, shape).astype(np.intp), np.broadcast_to(w, shape + (3,))


# ---------------------------------------------------------------------------------------------
# The model scene's join paths


@dataclass(frozen=True)
class ModelPath:
    """The evaluator's inputs for join paths (0, x2, x3) of the model scene (arrays of one shape):
    the cell coordinates ``r2``, ``r3`` (scene units) and ``phi`` (radians, [0, π]), and the vertex
    densities per unit area (module doc). ``f.weight(m, **path.inputs())`` evaluates them."""

    r2: np.ndarray
    r3: np.ndarray
    phi: np.ndarray
    camera_x2: np.ndarray
    camera_x3: np.ndarray
    light_start: np.ndarray
    light_x2: np.ndarray
    light_x1: np.ndarray

    def inputs(self) -> Dict[str, np.ndarray]:
        """The fields by name: the keyword arguments of :meth:`WeightFunction.weight`."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    def technique_densities(self) -> np.ndarray:
        """(p0, p1, p2) = (p_l(x2|x3)·p_l(x1|x2,x3), p_c(x2)·p_l(x2|x3), p_c(x2)·p_c(x3|x2)),
        shape (..., 3)."""
        return np.stack(
            [self.light_x2 * self.light_x1, self.camera_x2 * self.light_x2, self.camera_x2 * self.camera_x3], axis=-1
        )


def lobe_pdf(beta: float, theta: ArrayLike) -> np.ndarray:
    """The lobe's solid-angle pdf q(ϑ) = g(ϑ)·ϑ/sin ϑ, g(ϑ) = exp(−ϑ²/2β²)/(2πβ²) (docs/model.md
    §1, §9), ϑ and β in radians."""
    theta = _array(theta)
    g = np.exp(-theta * theta / (2.0 * beta * beta)) / (2.0 * math.pi * beta * beta)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(theta < 1e-4, 1.0 + theta * theta / 6.0, theta / np.sin(theta))
    return g * ratio


def start_density(scene: Scene, r: ArrayLike) -> np.ndarray:
    """The light's start density I(r)/Φ (per unit area) at radius `r` on plane 3: the first ring
    with inner ≤ r < outer, 0 outside every ring."""
    r = _array(r)
    out = np.zeros(r.shape)
    found = np.zeros(r.shape, dtype=bool)
    for ring in scene.rings:
        inside = ~found & (r >= ring.inner) & (r < ring.outer)
        out = np.where(inside, ring.level / scene.flux, out)
        found |= inside
    return out


def _scene_of(source: Union[Scene, WeightFunction, Mapping[str, Any]]) -> Scene:
    if isinstance(source, Scene):
        return source
    if isinstance(source, WeightFunction):
        return source.scene
    if isinstance(source, Mapping):
        return _scene(source.get("scene", source) if "format" in source else source)
    raise TypeError(f"model_path takes a Scene, a WeightFunction or a scene dict, not {type(source).__name__}")


def _points(x: ArrayLike, name: str) -> np.ndarray:
    a = _array(x)
    if a.ndim == 0 or a.shape[-1] != 2:
        raise ValueError(f"{name} must hold 2-D points (shape (n, 2) or (2,)), not shape {a.shape}")
    return a


def model_path(
    scene_or_function: Union[Scene, WeightFunction, Mapping[str, Any]],
    x2: ArrayLike,
    x3: ArrayLike,
    x3l: Optional[ArrayLike] = None,
) -> ModelPath:
    """The evaluator's inputs for the model scene's join paths (0, x2, x3) whose light paths start
    at `x3l` — the vertex densities a renderer of *that* scene passes, in its frame (plane 1 at
    z = 0 with the pixel at the origin, plane 2 at z = L2, plane 3 at z = L2 + L3).

    `x2` and `x3` are points on planes 2 and 3 and `x3l` the light path's start on plane 3, each
    of shape (n, 2) (or (2,) for one path; they broadcast), in the plane's (x, y) coordinates and
    the scene's unit. `x3l` is x3 itself except for a plane-3 merge: there the join path takes the
    camera's vertex x3c and the light path starts at x3l, within R of it (default: `x3`).

    Follows ``src/sim/weights/densities.rs`` operation by operation; the scene comes from a
    :class:`Scene`, a :class:`WeightFunction` or a parsed artifact (or its ``scene`` object).
    """
    scene = _scene_of(scene_or_function)
    x2 = _points(x2, "x2")
    x3 = _points(x3, "x3")
    x3l = x3 if x3l is None else _points(x3l, "x3l")
    x2x, x2y = x2[..., 0], x2[..., 1]
    x3x, x3y = x3[..., 0], x3[..., 1]
    x2x, x2y, x3x, x3y = np.broadcast_arrays(x2x, x2y, x3x, x3y)
    l2, l3 = scene.l2, scene.l3
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # u = (x2, L2), v = (x3 − x2, L3) in 3-D; nalgebra's norm is sqrt((x² + y²) + z²).
        vx, vy = x3x - x2x, x3y - x2y
        d1 = np.sqrt(x2x * x2x + x2y * x2y + l2 * l2)
        d2 = np.sqrt(vx * vx + vy * vy + l3 * l3)
        ax, ay, az = x2x / d1, x2y / d1, l2 / d1
        bx, by, bz = vx / d2, vy / d2, l3 / d2
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        theta = np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)
        q = lobe_pdf(scene.beta_rad, theta)
        d1_2, d2_2 = d1 * d1, d2 * d2
        camera_x2 = l2 * l2 / (math.pi * d1_2 * d1_2)
        camera_x3 = q * l3 / (d2_2 * d2)
        light_x2 = l3 * l3 / (math.pi * d2_2 * d2_2)
        light_x1 = q * l2 / (d1_2 * d1)
        lx, ly = x3l[..., 0], x3l[..., 1]
        light_start = np.broadcast_to(start_density(scene, np.sqrt(lx * lx + ly * ly)), d1.shape)
        cross = x2x * x3y - x2y * x3x
        dot = x2x * x3x + x2y * x3y
        phi = np.arctan2(np.abs(cross), dot)
    return ModelPath(
        r2=np.asarray(np.sqrt(x2x * x2x + x2y * x2y)),
        r3=np.asarray(np.sqrt(x3x * x3x + x3y * x3y)),
        phi=np.asarray(phi),
        camera_x2=np.asarray(camera_x2),
        camera_x3=np.asarray(camera_x3),
        light_start=np.array(light_start),
        light_x2=np.asarray(light_x2),
        light_x1=np.asarray(light_x1),
    )


# ---------------------------------------------------------------------------------------------
# Test vectors


@dataclass(frozen=True)
class WeightVectors:
    """Test vectors of ``optimis weights --vectors``: n merges drawn with the engine's samplers —
    the technique (n,), the join path's x2 and x3 and the light path's start x3l (each (n, 2), the
    model scene's frame and unit) — and the engine's weight of each (n,)."""

    technique: np.ndarray
    x2: np.ndarray
    x3: np.ndarray
    x3l: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return int(self.technique.shape[0])


def read_vectors(path: Union[str, "os.PathLike[str]"]) -> WeightVectors:
    """The test vectors of a CSV file written by ``optimis weights --vectors FILE`` (header
    ``technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight``), each number parsed to the nearest
    double (the file's shortest round-trip notation gives the engine's values exactly)."""
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip()
    if tuple(header.split(",")) != VECTOR_COLUMNS:
        raise ValueError(f"{path}: not a test-vector file (header {header!r}, expected {','.join(VECTOR_COLUMNS)!r})")
    # numpy's loadtxt parses each number to the nearest double, as the Rust writer's shortest
    # round-trip notation needs.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
        data = np.loadtxt(path, delimiter=",", skiprows=1, dtype=np.float64, ndmin=2)
    if data.size == 0:
        data = np.empty((0, len(VECTOR_COLUMNS)))
    if data.shape[1] != len(VECTOR_COLUMNS):
        raise ValueError(f"{path}: {data.shape[1]} columns, expected {len(VECTOR_COLUMNS)}")
    t = data[:, 0]
    if len(t) and (not np.all(np.isin(t, (0.0, 1.0, 2.0)))):
        raise ValueError(f"{path}: a technique outside 0, 1, 2")
    return WeightVectors(
        technique=t.astype(np.int64),
        x2=data[:, 1:3].copy(),
        x3=data[:, 3:5].copy(),
        x3l=data[:, 5:7].copy(),
        weight=data[:, 7].copy(),
    )


def vector_errors(function: WeightFunction, vectors: WeightVectors) -> np.ndarray:
    """Each vector's error |ours − weight| / (max(1, |weight|)·(1 + Σ|β_h|)) — relative to the size
    of the terms, since a stack's table and β·w_h may cancel; 0 where both are the same (NaN
    included), ∞ where only one is NaN."""
    path = model_path(function, vectors.x2, vectors.x3, vectors.x3l)
    ours = function.weight_of(vectors.technique, path)
    theirs = vectors.weight
    with np.errstate(invalid="ignore", over="ignore"):
        scale = np.maximum(1.0, np.abs(theirs)) * (1.0 + function.beta_sum)
        err = np.abs(ours - theirs) / scale
    same = (ours == theirs) | (np.isnan(ours) & np.isnan(theirs))
    return np.where(same, 0.0, np.where(np.isnan(err), np.inf, err))


def check_vectors(
    function: Union[WeightFunction, Source], vectors: Union[WeightVectors, str, "os.PathLike[str]"]
) -> float:
    """The worst error of `function` (or an artifact to :meth:`~WeightFunction.load`) on the test
    `vectors` (or their CSV file): max over the merges of
    |ours − weight| / (max(1, |weight|)·(1 + Σ|β_h|)). A faithful port gives ≲ 1e-12."""
    if not isinstance(function, WeightFunction):
        function = WeightFunction.load(function)
    if not isinstance(vectors, WeightVectors):
        vectors = read_vectors(vectors)
    if len(vectors) == 0:
        return 0.0
    return float(vector_errors(function, vectors).max())
