"""A finished run's plots: written after ``rig run``, remade by ``rig plot RUN``, and a
folder that is no run is one line."""

import pytest

from rig.cli import main
from rig.plots import PLOTS

pytestmark = pytest.mark.closed_loop

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_a_run_leaves_its_plots_and_rig_plot_remakes_them(tmp_path, free_instance, capsys):
    run = tmp_path / "run"
    assert main(["run", "takeoff_hover_land", "--duration", "4", "--instance",
                 str(free_instance()), "--out", str(run)]) == 0  # fmt: skip
    assert f"plots:         {run}/{{position.png," in capsys.readouterr().err
    for name in PLOTS:
        png = run / f"{name}.png"
        assert png.read_bytes()[:8] == PNG_SIGNATURE
        png.unlink()
    assert main(["plot", str(run)]) == 0
    assert all((run / f"{name}.png").stat().st_size > 10_000 for name in PLOTS)


def test_plot_of_a_folder_without_a_run_is_one_line(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 1
    assert (
        capsys.readouterr().err
        == f"rig: error: {tmp_path / 'rig.ulg'}: no such log (is this a run folder?)\n"
    )


@pytest.mark.parametrize(
    ("content", "says"),
    [(b"not a ulog at all", "not a readable ULog"),
     (b"ULog\x01\x12\x35" + b"\x00" * 40, "no vehicle_local_position_groundtruth")],
)  # fmt: skip
def test_plot_of_a_damaged_log_is_one_line(tmp_path, capsys, content, says):
    (tmp_path / "rig.ulg").write_bytes(content)
    assert main(["plot", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"rig: error: {tmp_path / 'rig.ulg'}: {says}")
    assert err.count("\n") == 1
