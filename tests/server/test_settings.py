"""The service's settings: a simulated rig's speed no clock can run at is refused where it is given."""
import pytest

from server.settings import Settings, SettingsError


@pytest.mark.parametrize("speed", ["0", "-1", "nan", "inf"])
def test_an_impossible_sim_speed_is_refused(speed, tmp_path):
    """-1 started a service whose embedded rig streamed nothing ("no accelerometer frames within 2 s" at the
    first sweep); nan passed a `<= 0` check."""
    with pytest.raises(SettingsError, match="sim_speed must be positive"):
        Settings.load(env={"SHAKEID_SIM_SPEED": speed}, data_dir=tmp_path)
    assert Settings.load(env={"SHAKEID_SIM_SPEED": "10"}, data_dir=tmp_path).sim_speed == 10.0
