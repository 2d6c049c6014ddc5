"""What every entry point does around Hydra (unps.cli): paths, one-line errors, Ctrl-C."""

import os
import subprocess
import sys

import pytest

from unps.cli import INTERRUPTED, command_line, expand_home
from unps.errors import Interrupted


@pytest.mark.parametrize("argument, expected", [
    ("subject.root=~/captures/mug", "subject.root=" + os.path.expanduser("~") + "/captures/mug"),
    ("subject.root=~", "subject.root=" + os.path.expanduser("~")),
    ("light=gt", "light=gt"),
    ("subject.root=/data/~old", "subject.root=/data/~old"),
    ("subject.root='~/mug'", "subject.root='~/mug'"),          # quoted: Hydra's to read
])
def test_a_home_folder_after_the_equals_sign_is_written_out(argument, expected):
    assert expand_home(argument) == expected


def run_wrapped(error: BaseException, capsys) -> tuple[int, str]:
    def hydra_main():
        raise error

    with pytest.raises(SystemExit) as exit_:
        command_line(hydra_main)()
    return exit_.value.code, capsys.readouterr().err


def test_ctrl_c_exits_130_with_what_to_do_next(capsys):
    code, err = run_wrapped(Interrupted("interrupted at step 25 of 40: the same command resumes"), capsys)
    assert code == INTERRUPTED == 130 and "interrupted at step 25 of 40" in err
    code, err = run_wrapped(KeyboardInterrupt(), capsys)
    assert code == 130 and "the same command starts it again" in err


def test_errors_about_the_command_line_and_the_run_folder_take_one_line_and_exit_2(capsys):
    from hydra.errors import MissingConfigException

    code, err = run_wrapped(MissingConfigException("Could not find 'preset/x'\n\nAvailable options in "
                                                   "'preset':\n\tfast\n\tpaper\n", "preset/x"), capsys)
    assert code == 2 and err.count("\n") == 1 and "Available options in 'preset': fast paper" in err
    code, err = run_wrapped(FileExistsError(17, "File exists", "/tmp/taken"), capsys)
    assert code == 2 and err.count("\n") == 1 and "cannot write /tmp/taken: File exists" in err


def test_a_task_error_is_not_taken_for_a_command_line_error():
    from hydra.errors import InstantiationException

    def hydra_main():
        raise InstantiationException("a bug in a target")

    with pytest.raises(InstantiationException):
        command_line(hydra_main)()


@pytest.mark.slow
def test_the_readmes_own_photos_line_runs_as_pasted_into_bash(tmp_path):
    """``python -m unps.fit subject=folder subject.root=~/captures/mug``, unquoted, through bash."""
    from unps.data.analytic import render_lambertian
    from unps.data.writer import write_diligent

    folder = tmp_path / "captures" / "mug"
    write_diligent(render_lambertian("sphere", size=32, n_lights=12, seed=3), folder)
    (folder / "light_directions.txt").unlink()        # own photos: no lights, no mask
    (folder / "mask.png").unlink()
    command = (f"{sys.executable} -m unps.fit subject=folder subject.root=~/captures/mug "
               f"method=woodham light=estimated hydra.run.dir={tmp_path / 'run'}")
    done = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "HOME": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "run" / "metrics.json").is_file() and (tmp_path / "run" / "mask.png").is_file()
    assert "mask was found from the images" in done.stderr
