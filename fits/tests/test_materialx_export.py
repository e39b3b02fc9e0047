"""`ndfit export --to materialx|openpbr` in the real MaterialX library (PyPI `MaterialX`): the documents
validate against the standard libraries, generate GLSL, and connect the shader's tangent input to a
tangent turned about the normal by the export's `tangent_angle`.

Skips when the ndfit binary or the MaterialX module is absent.
"""

import json
import math
import os
import subprocess

import numpy as np
import pytest

mx = pytest.importorskip("MaterialX")
from MaterialX import PyMaterialXGenGlsl as mx_glsl  # noqa: E402
from MaterialX import PyMaterialXGenShader as mx_gen  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NDFIT = os.environ.get("NDFIT", os.path.join(ROOT, "target", "release", "ndfit"))
NDFIT = NDFIT if os.path.isabs(NDFIT) else os.path.join(ROOT, NDFIT)

pytestmark = pytest.mark.skipif(
    not os.access(NDFIT, os.X_OK), reason=f"SKIP: no ndfit binary at {NDFIT} (cargo build --release, or set NDFIT)"
)

FIT = {"model": "ggx-aniso", "params": {"alpha_x": 0.4, "alpha_y": 0.1, "theta_z": -1.043}}
SHADER = {"materialx": ("ndfit_conductor", "tangent"), "openpbr": ("ndfit_surface", "geometry_tangent")}


def ndfit(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout


def rotate3d(v, amount_deg, axis):
    """MaterialX's rotate3d as its library defines it (mx_rotate_vector3.glsl, read below)."""
    a = math.radians(amount_deg)
    axis = axis / np.linalg.norm(axis)
    return v * math.cos(a) + np.cross(v, axis) * math.sin(a) + axis * np.dot(axis, v) * (1 - math.cos(a))


@pytest.mark.parametrize("target", sorted(SHADER))
def test_document_validates_generates_glsl_and_turns_the_tangent(tmp_path, target):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps(FIT))
    text = ndfit("export", fit, "--to", target)
    angle = json.loads(ndfit("export", fit, "--to", target, "--json"))["tangent_angle"]

    lib = mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    doc = mx.createDocument()
    doc.importLibrary(lib)
    mx.readFromXmlString(doc, text)
    ok, msg = doc.validate()
    assert ok, msg

    shader_name, port = SHADER[target]
    node = doc.getNode(shader_name)
    tangent = node.getInput(port)
    assert tangent is not None and tangent.getConnectedNode() is not None, f"{port} not connected"
    rot = tangent.getConnectedNode()
    assert rot.getCategory() == "rotate3d"
    assert rot.getInput("in").getConnectedNode().getCategory() == "tangent"
    assert rot.getInput("axis").getConnectedNode().getCategory() == "normal"

    # The library's rotate3d, applied to the scan's +x about +z, must land on the export's tangent azimuth.
    glsl = search.find("libraries/stdlib/genglsl/mx_rotate_vector3.glsl").asString()
    assert "cross(_in, axis) * s" in open(glsl).read()
    amount = rot.getInput("amount").getValue()
    t = rotate3d(np.array([1.0, 0.0, 0.0]), amount, np.array([0.0, 0.0, 1.0]))
    assert np.allclose(t, [math.cos(angle), math.sin(angle), 0.0], atol=1e-5), (t, angle)

    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(search)
    material = doc.getNode("ndfit")
    shader = gen.generate("ndfit", material, ctx)
    src = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    assert "mx_rotate_vector3" in src


def mirror_fit(answer, sigma=40e-9):
    """A fit whose answer is a mirror: the mirror shares of Gaussian heights, exp(-(2 k sigma cos t)^2)."""
    spec = [
        {"theta_deg": t, "wavelength_nm": l, "weight": math.exp(-((4.0 * math.pi / (l * 1e-9) * sigma * math.cos(math.radians(t))) ** 2))}
        for l in (450.0, 550.0, 650.0)
        for t in (0.0, 30.0, 45.0, 60.0, 75.0)
    ]
    optics = {"regime": "wave", "wavelength_nm": [450.0, 550.0, 650.0], "coherence_m": 1.8925e-05, "specular": spec}
    if answer != "mirror":
        optics["haze"] = {"model": "ggx", "params": {"alpha": 0.05}}
    return {"schema": "ndfit.fit/1", "model": "ggx", "params": {"alpha": 0.3}, "selection": {"answer": answer}, "optics": optics}


@pytest.mark.parametrize("target", sorted(SHADER))
@pytest.mark.parametrize("answer", ["mirror", "mirror+ggx"])
def test_mirror_document_validates_and_generates_glsl(tmp_path, target, answer):
    """A mirror answer's document (a smooth conductor; with haze a `mix` of it, `bg`, and the haze, `fg`, at
    the export's constant weight) validates against the standard libraries and generates GLSL."""
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps(mirror_fit(answer)))
    text = ndfit("export", fit, "--to", target)
    exported = json.loads(ndfit("export", fit, "--to", target, "--json"))
    lib = mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    doc = mx.createDocument()
    doc.importLibrary(lib)
    mx.readFromXmlString(doc, text)
    ok, msg = doc.validate()
    assert ok, msg
    mixes = [n for n in doc.getNodes() if n.getCategory() == "mix"]
    if answer == "mirror":
        assert not mixes
    else:
        (mix,) = mixes
        assert mix.getInput("bg").getConnectedNode().getName() == "ndfit_mirror"
        assert mix.getInput("fg").getConnectedNode().getName() == "ndfit_haze"
        # MaterialX holds a float input as float32.
        assert abs(mix.getInput("mix").getValue() - exported["weight"]) < 1e-7
    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(search)
    shader = gen.generate("ndfit", doc.getNode("ndfit"), ctx)
    assert shader.getSourceCode(mx_gen.PIXEL_STAGE)
