"""crosscheck.py's logic against a fake `ndfit` (a small Python script speaking the contract's CLI), so that
agreement, disagreement and failing commands are all exercised without the Rust binary."""

import json
import os
import stat
import subprocess
import sys
import textwrap

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
CROSSCHECK = os.path.join(os.path.dirname(HERE), "crosscheck.py")

FAKE = textwrap.dedent(
    """\
    #!{python}
    # A stand-in for ndfit: a "scan" is a JSON file naming a model and parameters; ndf samples it.
    import json, os, sys
    sys.path.insert(0, {fits!r})
    from ndfitpy import synthetic, fitjson, models
    from ndfitpy.bins import write_ndf_csv
    from ndfitpy.fit import fit

    def opt(name, default=None):
        a = sys.argv
        return a[a.index(name) + 1] if name in a else default

    def bins_of(scan):
        try:
            spec = json.load(open(scan))
        except Exception as e:
            print(f"ndfit: {{scan}}: not a scan: {{e}}", file=sys.stderr); sys.exit(2)
        return synthetic.sampled_bins(spec["model"], spec["params"], 100_000, synthetic.grid_for(0.3, 32, 48), seed=1)

    cmd = sys.argv[1]
    if cmd == "synth":
        if opt("--surface") != "ellipsoid":
            print("ndfit: only ellipsoid surfaces here", file=sys.stderr); sys.exit(2)
        ax = float(opt("--alpha-x", 0.3))
        p = [ax, float(opt("--alpha-y", ax))] + [float(opt(k, 0)) for k in ("--theta-x", "--theta-y", "--theta-z")]
        json.dump({{"model": "ellipsoid", "params": p}}, open(sys.argv[2], "w"))
    elif cmd == "ndf" and opt("-o").endswith(".json"):
        # The NDF's JSON: what crosscheck reads of it (the normal scheme; no quantization, no frame needed).
        bins_of(sys.argv[2])
        json.dump({{"options": {{"normals": "central"}}, "quantization": None}}, open(opt("-o"), "w"))
    elif cmd == "ndf":
        write_ndf_csv(opt("-o"), bins_of(sys.argv[2]))
    elif cmd == "fit":
        model = opt("--model")
        if os.environ.get("FAKE_FAIL") == model:
            print(f"ndfit: {{sys.argv[2]}}: fit failed on purpose", file=sys.stderr); sys.exit(2)
        b = bins_of(sys.argv[2])
        r = fit(b, model, method="lbfgs")
        k = float(os.environ.get("FAKE_SCALE", "1"))
        for n in r.params:
            if n.startswith("alpha"):
                r.params[n] *= k
        fitjson.write_fit(opt("-o"), r, b)
    """
)


@pytest.fixture()
def fake(tmp_path):
    p = tmp_path / "ndfit"
    p.write_text(FAKE.format(python=sys.executable, fits=os.path.dirname(HERE)))
    p.chmod(p.stat().st_mode | stat.S_IEXEC)
    return str(p)


def _run(fake, tmp_path, env_extra=None, models="ggx,ellipsoid", known=None):
    env = dict(os.environ, **(env_extra or {}))
    if "NDFIT_REQUIRE_SHARED" not in (env_extra or {}):
        env.pop("NDFIT_REQUIRE_SHARED", None)  # these runs point --scans at an absent folder on purpose
    out = tmp_path / "rows.json"
    known_path = tmp_path / "known.json"
    known_path.write_text(json.dumps(known or []))
    r = subprocess.run(
        [sys.executable, CROSSCHECK, "--ndfit", fake, "--models", models, "--scans", str(tmp_path / "absent"),
         "--size", "64", "--only", "ggx", "--json", str(out), "--known", str(known_path), "--no-e2e"],
        capture_output=True, text=True, env=env, timeout=600,
    )
    rows = json.loads(out.read_text()) if out.exists() else None
    return r, rows


def test_agreement_passes(fake, tmp_path):
    r, rows = _run(fake, tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.strip().splitlines()
    assert lines[-1] == "crosscheck: 2 passed, 0 failed"
    assert any(ln.startswith("SKIP real scans") for ln in lines)
    assert all(row["verdict"] == "ok" and row["delta"] < 1e-3 for row in rows)


def test_absent_shared_scans_fail_when_required(fake, tmp_path):
    """NDFIT_REQUIRE_SHARED=1 turns the SKIP of absent real scans into a failure that names the folder."""
    r, rows = _run(fake, tmp_path, {"NDFIT_REQUIRE_SHARED": "1"})
    assert r.returncode == 1, r.stdout + r.stderr
    lines = r.stdout.strip().splitlines()
    assert any(ln.startswith("FAIL real scans") and "absent" in ln for ln in lines)
    assert lines[-1].startswith("crosscheck: 2 passed, 0 failed; missing (NDFIT_REQUIRE_SHARED is set): ")
    assert lines[-1].endswith("absent")


def test_disagreement_fails(fake, tmp_path):
    """Alphas 1% off on the Rust side: delta ~ 1e-2 and a worse objective, both reported."""
    r, rows = _run(fake, tmp_path, {"FAKE_SCALE": "1.01"})
    assert r.returncode == 1
    assert r.stdout.strip().splitlines()[-1] == "crosscheck: 0 passed, 2 failed"
    assert "NDFs differ" in r.stdout and "rust objective worse" in r.stdout
    assert "the Rust side is wrong" in r.stdout


def test_known_findings_are_reported_and_skipped(fake, tmp_path):
    known = [{"scan": "synth-ggx", "model": "ggx", "side": "rust", "reason": "test reason"}]
    r, rows = _run(fake, tmp_path, {"FAKE_SCALE": "1.01"}, known=known)
    assert r.returncode == 1  # the ellipsoid row is not known
    assert r.stdout.strip().splitlines()[-1] == "crosscheck: 0 passed, 1 failed, 1 skipped"
    assert "known finding (rust side): test reason" in r.stdout
    r, rows = _run(fake, tmp_path, known=known)
    assert r.returncode == 0 and "now pass" in r.stdout


def test_failing_command_is_a_row_not_a_traceback(fake, tmp_path):
    r, rows = _run(fake, tmp_path, {"FAKE_FAIL": "ellipsoid"})
    assert r.returncode == 1
    assert "Traceback" not in r.stdout + r.stderr
    assert "ndfit fit failed: exit 2: ndfit:" in r.stdout
    assert r.stdout.strip().splitlines()[-1] == "crosscheck: 1 passed, 1 failed"


def test_missing_binary_is_one_line(tmp_path):
    r = subprocess.run([sys.executable, CROSSCHECK, "--ndfit", str(tmp_path / "nope")], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "not an executable" in r.stderr
