"""`volsmpl hoi tune --grid`: what it accepts and what it refuses, before the database is read."""
import pytest
from volsmpl.apps.hoi.tune import parse_grid
from volsmpl.cli import main as cli_main


def test_grid_takes_weights_and_settings_by_name():
    grid = parse_grid(["w_pen=1e5,3e5", "scale-free-std=0,1,2"])
    assert grid == {"w_pen": [1e5, 3e5], "scale_free_std": [0.0, 1.0, 2.0]}


@pytest.mark.parametrize("spec, message", [
    ("iters=10,20", "give a weight or setting and its values"),
    ("w_pen=1e5,abc", "the values must be comma-separated numbers"),
    ("w_pen=-1", "give one or more finite weights >= 0"),
    ("rotation_after=0.2,1.5", "rotation_after must be a share of the steps in [0, 1), got 1.5"),
    ("contact_fraction=0", "contact_fraction must be in (0, 1], got 0.0"),
])
def test_a_wrong_grid_is_one_line_before_the_database_is_read(tmp_path, capsys, spec, message):
    rc = cli_main(["hoi", "tune", "--grid", spec, "--db", str(tmp_path / "no_db"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "no_db").exists()


@pytest.mark.parametrize("action", ["tune", "run"])
def test_a_negative_contact_margin_is_one_line_before_the_database_is_read(tmp_path, capsys, action):
    rc = cli_main(["hoi", action, "--contact-margin", "-0.01", "--db", str(tmp_path / "no_db"),
                   "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "--contact-margin" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "no_db").exists()
