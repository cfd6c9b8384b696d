"""tools/warp_coverage.py runs against an installed warp-lang and reports consistent lists.

The counts themselves are issue 14's goal (at most 10 names in "the rest"), tracked in
docs/language.md, not asserted here: they change as kdsl grows.
"""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("warp", reason="needs warp-lang (the bench extra)")

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tools" / "warp_coverage.py"


def _module():
    spec = importlib.util.spec_from_file_location("warp_coverage", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    # A fresh process: the public names are those of a bare ``import warp``.
    out = tmp_path_factory.mktemp("cov") / "coverage.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--json", str(out)], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "public names" in proc.stdout and "kernel builtins" in proc.stdout
    return json.loads(out.read_text())


def _check_groups(groups, expected_keys):
    assert tuple(groups) == expected_keys
    seen = set()
    for names in groups.values():
        assert names == sorted(names)
        assert len(set(names)) == len(names)
        assert not seen & set(names), "a name is in two groups"
        seen |= set(names)
    return seen


def test_public_names_consistent(report):
    mod = _module()
    p = report["public_names"]
    missing = _check_groups(p["missing_by_group"], mod.PUBLIC_GROUPS)
    assert len(missing) == p["missing"]
    assert p["kdsl_has"] + p["missing"] == p["total"]
    assert p["total"] > 400  # Warp's namespace, not an empty module
    import kdsl

    assert not any(hasattr(kdsl, n) for n in missing)
    assert not any(n.startswith("_") for n in missing)


def test_kernel_builtins_consistent(report):
    mod = _module()
    b = report["kernel_builtins"]
    missing = _check_groups(b["missing_by_group"], mod.BUILTIN_GROUPS)
    assert len(missing) == b["missing"]
    assert b["kdsl_has"] + b["missing"] == b["non_tile"]
    assert b["non_tile"] + b["tile"] + len(b["internal"]) == b["registry_total"]
    assert b["internal"] == sorted(b["internal"])
    found = b["kdsl_has_by_source"]
    assert not missing & set(found) and not missing & set(b["internal"])
    assert not any(n.startswith("tile_") for n in missing | set(found))
    # Names kdsl has had from the start, each from a different source.
    assert found["sin"] == "builtin" and found["tid"] == "builtin"
    assert found["quat_rotate"] == "stdlib"
    assert found["int32"] == "type" and found["range"] == "loop construct"


def test_grouping_rules():
    mod = _module()
    assert mod.public_group("Mesh") == "geometry"
    assert mod.public_group("MeshQueryAABBTiled") == "geometry"
    assert mod.public_group("launch_tiled") == "tiles"
    assert mod.public_group("ScopedCapture") == "cuda_graphs"
    assert mod.public_group("from_ipc_handle") == "multi_gpu_ipc"
    assert mod.public_group("Texture2D") == "textures_opengl_fabric"
    assert mod.public_group("indexedfabricarray") == "textures_opengl_fabric"
    assert mod.public_group("ScopedTimer") == "rest"
    assert mod.builtin_group("mesh_query_point") == "geometry"
    assert mod.builtin_group("closest_point_edge_edge") == "rest"
    assert mod.is_internal_builtin("add_inplace") and not mod.is_internal_builtin("add")
