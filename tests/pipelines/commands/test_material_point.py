"""python -m pipelines.material_point: stress against strain at one material
point."""

import numpy as np
import pytest


def test_stress_strain_command_writes_the_curve(tmp_path, capsys):
    """python -m pipelines.material_point: CSV and PNG of a von Mises uniaxial
    test whose plateau is the yield stress; bad material keys fail in one line."""
    from pipelines.material_point import main

    out = tmp_path / "vm.png"
    assert main(["material=von_mises", "material.yield_stress=2e4", "--path", "uniaxial",
                 "--strain", "0.05", "--steps", "50", "--out", str(out)]) == 0
    data = np.genfromtxt(out.with_suffix(".csv"), delimiter=",", names=True)
    assert out.exists() and len(data) == 51
    # Cauchy = Kirchhoff / J_E: on the plateau within the elastic volume change
    assert data["von_mises"][-1] == pytest.approx(2e4, rel=2e-2)
    assert main(["material=von_mises", "material.yield_stres=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: material.yield_stres: unknown key; accepted: model, rho, E, nu, yield_stress, "
                   "hardening"]
