"""One-line errors for the solver's settings in the config: the blow-up
detection (mpm.stepping.detection), the closed-form solutions (mpm.analytic) and the
reference run."""

import pytest

from helpers import compose_cfg, spec_for
from pipelines.config.validate import ConfigError, resolve


@pytest.mark.parametrize("override, key", [("detect.action=halt", "detect.action"),
                                           ("detect.energy_growth=0", "detect.energy_growth"),
                                           ("detect.min_J=1.5", "detect.min_J")])
def test_bad_detection_options_are_refused(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        resolve(compose_cfg([override]))


@pytest.mark.parametrize("overrides, key", [
    (["scene=vibrating_bar_2d", "scene.bodies.0.material.nu=0.3"], "scene.bodies[0].material"),
    (["scene=vibrating_bar_2d", "scene.gravity=[0,-9.81]"], "scene.gravity"),
    (["scene=vibrating_bar_2d", "scene.solution.mode=0"], "scene.solution.mode"),
    (["scene=vibrating_bar_2d", "+scene.solution.speed=1"], "scene.solution.speed"),
    (["scene=vortex_2d", "scene.bodies.0.material.model=fixed_corotated"], "scene.bodies[0].material.model"),
    (["scene=vortex_2d", "scene.bodies.0.shape.inner_radius=null"], "scene.bodies[0].shape"),
    (["scene=vortex_2d", "scene.solution.type=wave"], "scene.solution.type"),
])
def test_bad_solution_settings_name_the_key(overrides, key):
    with pytest.raises(ConfigError) as e:
        spec_for(overrides)
    assert e.value.key == key, str(e.value)


def test_missing_reference_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError) as e:
        spec_for([f"run.reference={tmp_path}"])
    assert e.value.key == "run.reference"
