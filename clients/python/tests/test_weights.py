"""The numpy evaluator of weights artifacts (optimis_client.weights): against the engine's test
vectors (``optimis weights --vectors``) for a table, a stack and per-path heuristics on three
scenes, and its checks of malformed artifacts.

The engine tests need the binary of ``OPTIMIS_BINARY`` (``.ci/python-client`` sets it); without
it they are skipped — unlike the server tests, they do not fall back to target/release/optimis,
which may predate ``optimis weights``.
"""

from __future__ import annotations

import copy
import json
import math
import os
import subprocess
from pathlib import Path
from typing import Any, Dict, List, Tuple

import numpy as np
import pytest

from optimis_client import (
    WeightFunction,
    WeightVectors,
    cell_index,
    check_vectors,
    model_path,
    read_vectors,
    vector_errors,
)

# The worst error a faithful port may show (docs: relative to the size of the terms).
TOLERANCE = 1e-12
# Merges per set of vectors.
VECTOR_COUNT = 100_000

RUN = ["--iterations", "3000", "--seed", "2", "--quiet"]
# name → the options of `optimis run` of the scene.
SCENES: Dict[str, List[str]] = {
    "paper": ["--preset", "paper-table1"],
    "paper-r0.01-beta8-l3-2": [
        "--preset",
        "paper-table1",
        "--set",
        "merge_radius=0.01",
        "--set",
        "scene.beta_deg=8",
        "--set",
        "scene.l3=2",
    ],
    "uniform-nb30": ["--preset", "uniform-illumination", "--set", "camera_paths=30"],
    # Beyond the three scenes above: four φ bins, so that the φ axis of the lookup is checked too.
    "paper-phi4": ["--preset", "paper-table1", "--set", "cells.phi_bins=4", "--set", "merge_radius=0.01"],
}
# None: the recommended row; the kind each artifact must be (None: whatever was recommended).
ROWS: List[Tuple[Any, Any]] = [
    (None, None),
    ("optimal_stacked", "stack"),
    ("optimal_cv", "table"),
    ("balance_planes23", "heuristic"),
]


def binary() -> Path:
    """The binary of OPTIMIS_BINARY; the test is skipped if it is unset."""
    value = os.environ.get("OPTIMIS_BINARY")
    if not value:
        pytest.skip("OPTIMIS_BINARY is unset: the weights tests need an optimis binary with `optimis weights`")
    path = Path(value).resolve()
    assert os.access(path, os.X_OK), f"OPTIMIS_BINARY={value} is not an executable"
    return path


def optimis(*args: str) -> None:
    """Run the binary with `args`; fail with its output if it fails."""
    done = subprocess.run([str(binary()), *args], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"optimis {' '.join(args)} exited with {done.returncode}:\n{done.stderr[-3000:]}"


@pytest.fixture(scope="module")
def documents(tmp_path_factory: pytest.TempPathFactory) -> Dict[str, Path]:
    """Lazily, each scene's moments document (3000 iterations, seed 2), made once per module."""
    work = tmp_path_factory.mktemp("weights")

    class Lazy(dict):  # type: ignore[type-arg]
        def __missing__(self, scene: str) -> Path:
            doc = work / f"{scene}.json"
            optimis("run", *SCENES[scene], *RUN, "--out", str(doc))
            self[scene] = doc
            return doc

    return Lazy()


def artifact(doc: Path, strategy: Any, tag: str) -> Tuple[Path, Path]:
    """The artifact of `strategy`'s row of `doc` (None: the recommended row) and its vectors."""
    out, vectors = doc.with_name(f"{tag}.weights.json"), doc.with_name(f"{tag}.vectors.csv")
    options = ["--strategy", strategy] if strategy else []
    optimis("weights", str(doc), "--out", str(out), "--vectors", str(vectors), "--vector-count", str(VECTOR_COUNT), *options)
    return out, vectors


@pytest.mark.parametrize("strategy,kind", ROWS, ids=[s or "recommended" for s, _ in ROWS])
@pytest.mark.parametrize("scene", list(SCENES))
def test_the_evaluator_gives_the_engines_weight_of_every_merge(
    documents: Dict[str, Path], scene: str, strategy: Any, kind: Any
) -> None:
    out, csv = artifact(documents[scene], strategy, f"{scene}-{strategy or 'recommended'}")
    f = WeightFunction.load(out)
    vectors = read_vectors(csv)
    assert len(vectors) >= VECTOR_COUNT
    assert set(np.unique(vectors.technique)) == {0, 1, 2}
    if strategy is None:
        assert f.recommended
    else:
        assert f.strategy == strategy and f.kind == kind
    errors = vector_errors(f, vectors)
    worst = check_vectors(f, vectors)
    print(f"{scene} {f.strategy} ({f.kind}): worst error {worst:.3e} on {len(vectors)} merges")
    assert worst == float(errors.max())
    assert worst <= TOLERANCE, f"{scene} {f.strategy}: worst error {worst:e} at merge {int(errors.argmax())}"
    # From the files as well.
    assert check_vectors(str(out), csv) == worst
    # The three techniques' weights of one path sum to 1 (the table to 1 − Σβ, each heuristic to 1).
    path = model_path(f, vectors.x2[:2000], vectors.x3[:2000], vectors.x3l[:2000])
    total = f.weights(**path.inputs()).sum(axis=-1)
    assert np.allclose(total, 1.0, rtol=0, atol=1e-12 * (1 + f.beta_sum)), total
    # One technique for all paths, and one path at a time, give the same weights.
    for m in range(3):
        np.testing.assert_array_equal(f.weight(m, **path.inputs()), f.weights(**path.inputs())[:, m])
    for k in range(5):
        one = model_path(f, vectors.x2[k], vectors.x3[k], vectors.x3l[k])
        assert one.r2.shape == ()
        assert float(f.weight_of(int(vectors.technique[k]), one)) == float(
            f.weight_of(vectors.technique[:2000], path)[k]
        )


# ---------------------------------------------------------------------------------------------
# Artifacts made here


def small_artifact() -> Dict[str, Any]:
    """A valid stack: 2 × 2 × 2 cells (r2 edges 0, 1; r3 edges 0, 0.5; two φ bins) and a switch."""
    table = []
    for i2 in range(2):
        for i3 in range(2):
            for ip in range(2):
                index = (i2 * 2 + i3) * 2 + ip
                table.append({"r2": i2, "r3": i3, "phi": ip, "w": [0.0, 0.1 * index, 0.5 - 0.1 * index]})
    return {
        "format": "optimis-weights",
        "version": 1,
        "strategy": "optimal_stacked",
        "recommended": False,
        "kind": "stack",
        "scene": {
            "l2": 1.0,
            "l3": 3.0,
            "beta_rad": 0.05,
            "merge_radius": 0.003,
            "light_paths": 1e7,
            "camera_paths": 100.0,
            "rings": [{"inner": 0.0, "outer": 0.02, "level": 3000.0}, {"inner": 0.02, "outer": 20.0, "level": 1.0}],
            "flux": 1260.0,
        },
        "cells": {"r2_edges": [0.0, 1.0], "r3_edges": [0.0, 0.5], "phi_bins": 2},
        "table": table,
        "heuristics": [
            {"name": "switch", "beta": 0.5, "formula": {"kind": "switch", "radius": 0.02}, "techniques": [False, True, True]}
        ],
        "provenance": {
            "fingerprint": "0" * 64,
            "iterations": 10,
            "coverage": [{"seed": 1, "ranges": [[0, 10]]}],
            "lambda": 1.0,
            "rms_percent": None,
            "rms_percent_stderr": None,
            "generator": "test",
        },
    }


def densities(n: int = 1) -> Dict[str, Any]:
    """Vertex densities for `n` paths (arbitrary positive values)."""
    return {
        "camera_x2": np.full(n, 0.3),
        "camera_x3": np.full(n, 2.0),
        "light_start": np.full(n, 1e-3),
        "light_x2": np.full(n, 0.01),
        "light_x1": np.full(n, 50.0),
    }


def test_a_small_stack_is_looked_up_as_the_rust_evaluator_does(tmp_path: Path) -> None:
    doc = small_artifact()
    f = WeightFunction.load(doc)
    assert f.kind == "stack" and f.cells is not None and f.cells.cells == 8 and f.beta_sum == 0.5
    # From a JSON string and from a file as well.
    assert WeightFunction.load(json.dumps(doc)).table.tolist() == f.table.tolist()  # type: ignore[union-attr]
    (tmp_path / "w.json").write_text(json.dumps(doc))
    assert WeightFunction.load(tmp_path / "w.json").table.tolist() == f.table.tolist()  # type: ignore[union-attr]
    # A signing server's artifact (its signature beside the weights) is read the same.
    signed = dict(doc, signature={"algorithm": "ed25519", "key_id": "k", "value": "AA=="})
    assert WeightFunction.load(signed).table.tolist() == f.table.tolist()  # type: ignore[union-attr]
    # A value on an edge belongs to the bin above; φ = π is in the last bin; negative and NaN → 0.
    r2 = np.array([0.0, 0.999, 1.0, 5.0, -1.0, np.nan, 0.2, 0.2])
    r3 = np.array([0.0, 0.5, 0.499, 7.0, 0.1, 0.1, np.nan, 0.1])
    phi = np.array([0.0, math.pi / 2, math.pi, math.pi, -0.1, np.nan, 1.0, 2.0])
    expected = [0, 3, 5, 7, 0, 0, 0, 1]
    assert cell_index(f.cells, r2, r3, phi).tolist() == expected
    w = f.weight(1, r2, r3, phi, **densities(len(r2)))
    # The table's w1 (0.1·cell) plus β·switch (technique 1 where r3 ≤ 0.02; NaN r3 is not).
    switch1 = np.where(r3 <= 0.02, 1.0, 0.0)
    np.testing.assert_allclose(w, 0.1 * np.array(expected) + 0.5 * switch1, rtol=0, atol=1e-15)
    w2 = f.weight(2, r2, r3, phi, **densities(len(r2)))
    np.testing.assert_allclose(w2, 0.5 - 0.1 * np.array(expected) + 0.5 * (1 - switch1), rtol=0, atol=1e-15)
    assert f.weight(0, r2, r3, phi, **densities(len(r2))).tolist() == [0.0] * len(r2)
    # Techniques as an array, per path; scalars give a 0-d array.
    t = np.array([0, 1, 2, 1, 0, 2, 1, 2])
    mixed = f.weight(t, r2, r3, phi, **densities(len(r2)))
    all3 = f.weights(r2, r3, phi, **densities(len(r2)))
    assert mixed.tolist() == all3[np.arange(len(t)), t].tolist()
    assert f.weight(1, 0.2, 0.01, 0.0, 0.3, 2.0, 1e-3, 0.01, 50.0).shape == ()
    with pytest.raises(ValueError, match="technique"):
        f.weight(3, 0.2, 0.01, 0.0, 0.3, 2.0, 1e-3, 0.01, 50.0)


def heuristic_artifact(formula: Dict[str, Any], techniques: List[bool]) -> Dict[str, Any]:
    doc = small_artifact()
    doc.update(kind="heuristic", cells=None, table=[], strategy="h")
    doc["heuristics"] = [{"name": "h", "beta": 1.0, "formula": formula, "techniques": techniques}]
    return doc


def test_the_heuristics_formulas() -> None:
    d = densities()
    p = np.array([0.01 * 50.0, 0.3 * 0.01, 0.3 * 2.0])
    args = (0.1, 0.01, 0.0)

    def all3(formula: Dict[str, Any], mask: List[bool]) -> np.ndarray:
        return WeightFunction.load(heuristic_artifact(formula, mask)).weights(*args, **d)[0]

    np.testing.assert_allclose(all3({"kind": "balance"}, [True] * 3), p / p.sum(), rtol=1e-15)
    q = np.array([0.0, p[1], p[2]])
    np.testing.assert_allclose(all3({"kind": "balance"}, [False, True, True]), q / q.sum(), rtol=1e-15)
    np.testing.assert_allclose(all3({"kind": "power", "exponent": 2.0}, [True] * 3), p**2 / (p**2).sum(), rtol=1e-15)
    assert all3({"kind": "one_technique", "technique": 2}, [True] * 3).tolist() == [0.0, 0.0, 1.0]
    # The correlation-aware counts: with N_F = N_B = 1 every count is 1 — the balance heuristic.
    ca = {"kind": "correlation_aware", "area": 1e-5, "light_paths": 1.0, "camera_paths": 1.0}
    np.testing.assert_allclose(all3(ca, [True] * 3), p / p.sum(), rtol=1e-15)
    # No sharing (A → 0): counts (N_F, N_F N_B, N_F N_B) ∝ (1, N_B, N_B).
    ca = {"kind": "correlation_aware", "area": 1e-300, "light_paths": 1e7, "camera_paths": 100.0}
    n = np.array([1.0, 100.0, 100.0])
    np.testing.assert_allclose(all3(ca, [True] * 3), n * p / (n * p).sum(), rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# Malformed artifacts


def refused(doc: Any, *words: str) -> str:
    """The message of the ValueError `doc` is refused with; it names each of `words`."""
    with pytest.raises(ValueError) as info:
        WeightFunction.load(doc)
    message = str(info.value)
    for word in words:
        assert word in message, f"{message!r} does not name {word!r}"
    return message


def test_another_format_or_version_is_refused() -> None:
    doc = small_artifact()
    doc["format"] = "optimis-moments"
    refused(doc, "format", "'optimis-moments'", "'optimis-weights'")
    for version in (2, 0, "1", 1.0, True, None):
        doc = small_artifact()
        doc["version"] = version
        refused(doc, "version", repr(version))
    doc = small_artifact()
    del doc["format"]
    refused(doc, "format")
    refused([1, 2], "JSON object")
    refused("{not json", "not JSON")


def test_a_table_cell_missing_twice_or_outside_is_refused() -> None:
    doc = small_artifact()
    del doc["table"][5]  # (1, 0, 1)
    refused(doc, "cell (1, 0, 1) is missing", "7 cells", "axes 8")
    doc = small_artifact()
    doc["table"][5] = dict(doc["table"][4])  # (1, 0, 0) twice, (1, 0, 1) missing
    refused(doc, "cell (1, 0, 0) is listed twice")
    doc = small_artifact()
    doc["table"].append(dict(doc["table"][0]))  # nine cells on eight
    refused(doc, "too many cells", "9 cells", "axes 8")
    doc = small_artifact()
    doc["table"][3]["phi"] = 2
    refused(doc, "cell (0, 1, 2) is outside the axes")
    doc = small_artifact()
    doc["table"][3]["w"] = [0.1, 0.2]
    refused(doc, "table[3].w", "3 weights")
    doc = small_artifact()
    doc["table"][3]["w"][1] = float("nan")
    refused(doc, "table[3].w[1]", "finite")


def test_too_many_cells_heuristics_or_rings_are_refused() -> None:
    doc = small_artifact()
    edges = [i * 0.01 for i in range(65)]  # 2 × 65 × 2 = 260 cells
    doc["cells"]["r3_edges"] = edges
    doc["table"] = [
        {"r2": i2, "r3": i3, "phi": ip, "w": [0.0, 0.25, 0.25]} for i2 in range(2) for i3 in range(65) for ip in range(2)
    ]
    refused(doc, "too many cells", "260", "256")
    doc = small_artifact()
    doc["heuristics"] = doc["heuristics"] * 17
    refused(doc, "too many heuristics", "17")
    doc = small_artifact()
    doc["scene"]["rings"] = doc["scene"]["rings"][:1] * 65
    refused(doc, "too many rings", "65")


def test_other_malformed_artifacts_are_refused() -> None:
    def edited(change: Any) -> Dict[str, Any]:
        doc = small_artifact()
        change(doc)
        return doc

    refused(edited(lambda d: d.update(extra=1)), "unknown field 'extra'")
    refused(edited(lambda d: d["scene"].update(l4=1.0)), "unknown field 'scene.l4'")
    refused(edited(lambda d: d["scene"].pop("flux")), "scene.flux is missing")
    refused(edited(lambda d: d.update(kind="lookup")), "kind 'lookup'")
    refused(edited(lambda d: d.update(cells=None)), "a table without cells")
    refused(edited(lambda d: d.update(table=[])), "cell (0, 0, 0) is missing")
    refused(edited(lambda d: d["cells"].update(r2_edges=[0.0, 1.0, 1.0])), "cells.r2_edges", "increase")
    refused(edited(lambda d: d["cells"].update(r3_edges=[0.1, 0.5])), "cells.r3_edges", "start at 0")
    refused(edited(lambda d: d["cells"].update(phi_bins=0)), "cells.phi_bins")
    refused(edited(lambda d: d.update(kind="heuristic")), "one heuristic and no table")
    refused(edited(lambda d: d["heuristics"][0]["formula"].update(kind="magic")), "heuristics[0].formula.kind 'magic'")
    refused(edited(lambda d: d["heuristics"][0]["formula"].pop("radius")), "heuristics[0].formula.radius is missing")
    refused(edited(lambda d: d["heuristics"][0].update(techniques=[True, True])), "heuristics[0].techniques")
    refused(edited(lambda d: d["heuristics"][0].update(beta="1")), "heuristics[0].beta", "number")
    refused(edited(lambda d: d["provenance"].pop("generator")), "provenance.generator is missing")
    no_table = heuristic_artifact({"kind": "balance"}, [True] * 3)
    no_table["kind"] = "table"
    refused(no_table, "a table artifact needs its table")
    refused(json.dumps(small_artifact()).replace("0.003", "NaN"), "NaN")
    # Optional members may be left out, as the Rust reader allows.
    doc = heuristic_artifact({"kind": "balance"}, [True] * 3)
    for key in ("cells", "table"):
        del doc[key]
    for key in ("lambda", "rms_percent", "rms_percent_stderr"):
        del doc["provenance"][key]
    WeightFunction.load(copy.deepcopy(doc))


def test_test_vectors_are_read_exactly(tmp_path: Path) -> None:
    csv = tmp_path / "v.csv"
    csv.write_text(
        "technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight\n"
        "2,-2.696350126425971e-1,1.3450076645708759e-2,-1.0834333314701385e0,-1.846992007683212e-1,"
        "-1.0819537694166816e0,-1.8691935961723272e-1,9.81498517752765e-1\n"
        "0,1e0,0e0,2e0,0e0,2e0,0e0,1e0\n"
    )
    v = read_vectors(csv)
    assert isinstance(v, WeightVectors) and len(v) == 2
    assert v.technique.tolist() == [2, 0]
    assert v.x2[0].tolist() == [-2.696350126425971e-1, 1.3450076645708759e-2]
    assert v.x3l[0, 1] == -1.8691935961723272e-1 and v.weight[0] == 9.81498517752765e-1
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="header"):
        read_vectors(tmp_path / "bad.csv")
    # Errors: 0 where equal, relative to max(1, |w|)·(1 + Σ|β|), ∞ where only one side is NaN.
    f = WeightFunction.load(heuristic_artifact({"kind": "one_technique", "technique": 0}, [True] * 3))
    shifted = WeightVectors(v.technique, v.x2, v.x3, v.x3l, np.array([0.5, np.nan]))
    assert vector_errors(f, shifted).tolist() == [0.25, math.inf]
