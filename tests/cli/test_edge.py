"""The edge of every stage: outputs checked before any work and landed together, operating-system
errors and signals as one line, temporaries of killed runs cleaned."""

import errno
import hashlib
import logging
import os
import signal
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import atomic
from plenocli.pipeline.config import load_config
from plenocli.pipeline.runner import plan

ROOT = Path(__file__).resolve().parents[2]
CAPTURE = ROOT / "fixtures" / "dualpixel" / "capture.dng"
FRAMES_ONLY = [".frames.tif.plenocli.json", "frames.tif"]  # the fixture's output and its record


@pytest.fixture
def frames(tmp_path):
    """A decoded capture to feed bias."""
    out = tmp_path / "frames.tif"
    result = CliRunner().invoke(cli, ["decode", str(CAPTURE), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    return out


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line(result) -> str:
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "Traceback" not in result.output and "internal error" not in result.output
    return lines[0]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_two_outputs_on_one_path_are_refused_before_any_work(tmp_path, frames):
    out = tmp_path / "b.tif"
    result = invoke("flat", frames, "--white", frames, "-o", out, "--save-gain", out)
    assert result.exit_code == 1
    assert "given for two outputs" in one_line(result)
    assert sorted(p.name for p in tmp_path.iterdir()) == FRAMES_ONLY


def test_two_outputs_one_file_through_a_linked_folder_are_refused(tmp_path, frames):
    """audit 20 W4: -o real/g.tif --save-gain link/g.tif (link -> real) wrote both, one lost."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    result = invoke("flat", frames, "--white", frames, "-o", tmp_path / "real" / "g.tif",
                    "--save-gain", tmp_path / "link" / "g.tif")
    assert result.exit_code == 1 and "given for two outputs" in one_line(result)
    assert not list((tmp_path / "real").iterdir())


def test_an_output_that_is_an_input_is_refused(tmp_path, frames):
    before = digest(frames)
    result = invoke("flat", frames, "--white", tmp_path / "w.tif", "-o", tmp_path / "b.tif",
                    "--save-gain", frames)
    assert result.exit_code == 1 and "also an input" in one_line(result)
    assert digest(frames) == before


def test_when_the_second_output_fails_the_first_is_not_left(tmp_path, frames, monkeypatch):
    import plenocli.pipeline.stages.bias as stage

    def disk_full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(stage, "write_png", disk_full)
    result = invoke("bias", frames, "-o", tmp_path / "b.tif", "--preview", tmp_path / "b.png")
    assert result.exit_code == 1
    assert "no space left" in one_line(result)
    assert sorted(p.name for p in tmp_path.iterdir()) == FRAMES_ONLY  # no b.tif, no .part


class _Said(logging.Handler):
    """The messages of the plenocli log, each with whether ``watched`` existed when it came."""

    def __init__(self, watched: Path):
        super().__init__()
        self.watched, self.said = watched, []

    def emit(self, record):
        self.said.append((record.getMessage(), self.watched.exists()))


@pytest.fixture
def said(tmp_path):
    from plenocli.progress import log

    handler = _Said(tmp_path / "b.tif")
    log.addHandler(handler)
    yield handler
    log.removeHandler(handler)


def test_the_success_line_comes_after_the_outputs_landed(tmp_path, frames, said):
    # audit 8 E8: "bias: IN -> OUT" was said while OUT was still a temporary
    result = invoke("bias", frames, "-o", tmp_path / "b.tif", "--preview", tmp_path / "b.png")
    assert result.exit_code == 0, result.output
    assert [landed for text, landed in said.said if text.startswith("bias: ")] == [True]


def test_no_success_line_when_a_later_output_fails(tmp_path, frames, monkeypatch, said):
    # audit 8 E8: the success line was printed, then "Error: ...: no space left"
    import plenocli.pipeline.stages.bias as stage

    def disk_full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(stage, "write_png", disk_full)
    result = invoke("bias", frames, "-o", tmp_path / "b.tif", "--preview", tmp_path / "b.png")
    assert result.exit_code == 1 and "no space left" in one_line(result)
    assert [text for text, _ in said.said if text.startswith("bias: ")] == []


def _under_a_file(folder: Path) -> Path:
    (folder / "file").write_text("x")
    return folder / "file" / "b.tif"


def _a_folder(folder: Path) -> Path:
    (folder / "folder.tif").mkdir()
    return folder / "folder.tif"


@pytest.mark.parametrize("make_bad, code, expected", [
    (_under_a_file, 1, "is a file, not a folder"),
    (lambda d: d / ("x" * 300 + ".tif"), 1, "too long"),
    (_a_folder, 2, "is a directory"),  # click's own check of -o: a usage error
])
def test_unwritable_outputs_are_one_line(tmp_path, frames, make_bad, code, expected):
    result = invoke("bias", frames, "-o", make_bad(tmp_path))
    assert result.exit_code == code
    assert expected in result.output.strip().splitlines()[-1]


def test_a_read_only_folder_is_one_line(tmp_path, frames, monkeypatch):
    folder = tmp_path / "ro"
    folder.mkdir()
    real_access = os.access
    monkeypatch.setattr(atomic.os, "access",  # root ignores permission bits: say it is read-only
                        lambda p, mode: False if Path(p) == folder else real_access(p, mode))
    result = invoke("bias", frames, "-o", folder / "b.tif")
    assert result.exit_code == 1
    assert "not writable" in one_line(result)


def test_sigterm_is_handled_like_ctrl_c(tmp_path, frames, monkeypatch):
    import plenocli.pipeline.stages.bias as stage

    real_write = stage.tiffio.write_image

    def write_then_terminated(path, *args, **kwargs):
        real_write(path, *args, **kwargs)  # the temporary exists now; a SIGTERM arrives
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(stage.tiffio, "write_image", write_then_terminated)
    result = invoke("bias", frames, "-o", tmp_path / "b.tif")
    assert result.exit_code == 143
    assert "terminated; no partial output was kept" in one_line(result)
    assert sorted(p.name for p in tmp_path.iterdir()) == FRAMES_ONLY
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored


def test_a_sigterm_between_two_renames_lands_every_output(tmp_path, frames, monkeypatch):
    """The outputs (here the image and its record) land together even when a SIGTERM arrives
    after the first rename: the signal waits for the last one, then ends the command."""
    real_replace = os.replace
    renamed = []

    def replace_then_terminated(src, dst):
        real_replace(src, dst)
        renamed.append(Path(dst).name)
        if len(renamed) == 1:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(10000):  # without the signals held, the handler runs here
                pass

    monkeypatch.setattr(os, "replace", replace_then_terminated)
    result = invoke("bias", frames, "-o", tmp_path / "b.tif")
    monkeypatch.undo()
    assert result.exit_code == 143, result.output
    assert len(renamed) == 2, (renamed, sorted(p.name for p in tmp_path.iterdir()))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        FRAMES_ONLY + [".b.tif.plenocli.json", "b.tif"])


class _TerminatedWhileCollected:
    """An object whose ``__del__`` receives a SIGTERM: Python drops the handler's exception
    (as it does in a weakref callback), so only the noted request can stop the stage."""

    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(10000):  # the handler runs here, inside __del__
            pass


def test_a_sigterm_whose_exception_is_lost_still_terminates(tmp_path, frames, monkeypatch):
    import plenocli.pipeline.stages.bias as stage

    real_write = stage.tiffio.write_image

    def write_then_collected(path, *args, **kwargs):
        real_write(path, *args, **kwargs)
        _TerminatedWhileCollected()  # collected at once

    monkeypatch.setattr(stage.tiffio, "write_image", write_then_collected)
    result = invoke("bias", frames, "-o", tmp_path / "b.tif")
    assert result.exit_code == 143, result.output
    assert "terminated; no partial output was kept" in one_line(result)
    assert sorted(p.name for p in tmp_path.iterdir()) == FRAMES_ONLY


def test_temporaries_of_killed_runs_are_removed(tmp_path, frames):
    out = tmp_path / "b.tif"
    host = atomic._HOST
    dead = tmp_path / f".b.tif.{host}-{2**22 + 12345}.abcd1234.part"
    live = tmp_path / f".b.tif.{host}-{os.getpid()}.efgh5678.part"
    dead.write_bytes(b"left by SIGKILL")
    live.write_bytes(b"another run still writing")
    assert invoke("bias", frames, "-o", out, "-q").exit_code == 0
    assert out.is_file() and not dead.exists() and live.exists()


@pytest.mark.parametrize("mask", [0o077, 0o002, 0o022])
def test_outputs_follow_the_umask_and_keep_the_mode_they_replace(tmp_path, frames, mask):
    # audit 7 E5: every output was 0644 whatever the umask, and a 0600 output widened to 0644
    old = os.umask(mask)
    try:
        assert atomic.current_umask() == mask
        result = invoke("bias", frames, "-o", tmp_path / "b.tif", "-q")
        assert result.exit_code == 0, result.output
        for name in ("b.tif", ".b.tif.plenocli.json"):
            assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~mask, name
        (tmp_path / "b.tif").chmod(0o640)
        result = invoke("bias", frames, "-o", tmp_path / "b.tif", "--smooth", "3", "-q")
        assert result.exit_code == 0, result.output
        assert (tmp_path / "b.tif").stat().st_mode & 0o777 == 0o640
    finally:
        os.umask(old)


def test_an_output_that_is_a_symbolic_link_is_written_through(tmp_path, frames):
    # audit 7 E6: the message named the link's target but the link was replaced by the file
    (tmp_path / "old.tif").write_text("old")
    (tmp_path / "b.tif").symlink_to("old.tif")
    (tmp_path / "p.png").symlink_to("nowhere.png")  # dangling: made, as the shell's > does
    result = invoke("bias", frames, "-o", tmp_path / "b.tif", "--preview", tmp_path / "p.png")
    assert result.exit_code == 0, result.output
    assert os.readlink(tmp_path / "b.tif") == "old.tif"
    assert os.readlink(tmp_path / "p.png") == "nowhere.png"
    assert (tmp_path / "old.tif").read_bytes()[:2] in (b"II", b"MM")
    assert (tmp_path / "nowhere.png").read_bytes()[:4] == b"\x89PNG"
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  bias: {{input: {frames}, output: {tmp_path / 'b.tif'}}}\n")
    assert invoke("run", config).exit_code == 0
    assert [d.reason for d in plan(load_config(config))] == ["up to date"]  # its record matches


@pytest.mark.parametrize("role", ["-o", "--preview"])
def test_an_output_that_is_a_symbolic_link_loop_is_refused_before_any_work(tmp_path, frames,
                                                                          role):
    # audit 10 I1: decode/calibrate -o LOOP was an internal error (after the work), a looping
    # --preview or --json was replaced by a regular file with exit 0
    (tmp_path / "a.png").symlink_to("b.png")
    (tmp_path / "b.png").symlink_to("a.png")
    (tmp_path / "l.tif").symlink_to("l.tif")
    out = {"-o": tmp_path / "l.tif", "--preview": tmp_path / "a.png"}
    words = ["-o", tmp_path / "v.tif", "--preview", tmp_path / "p.png"]
    words[words.index(role) + 1] = out[role]
    result = invoke("bias", frames, *words)
    assert result.exit_code == 1
    assert f"cannot write {out[role]}: it is a symbolic link loop" in one_line(result)
    assert not (tmp_path / "v.tif").exists() and not (tmp_path / "p.png").exists()
    assert [os.readlink(tmp_path / n) for n in ("a.png", "b.png", "l.tif")] == [
        "b.png", "a.png", "l.tif"]


def test_an_output_folder_that_is_a_dangling_link_is_named_so(tmp_path, frames):
    (tmp_path / "out").symlink_to("nowhere")
    result = invoke("bias", frames, "-o", tmp_path / "out" / "b.tif")
    assert result.exit_code == 1
    assert "symbolic link to nowhere, which does not exist" in one_line(result)
    assert not (tmp_path / "nowhere").exists()


def test_an_output_name_that_is_not_utf8_is_written_with_its_record(tmp_path, frames):
    # audit 7 I2: a Latin-1 byte in an output name (a lone surrogate to Python) was an internal
    # error where the temporary's name was made; inputs with such names were read
    name = os.fsdecode(b"lat\xe9.tif")
    result = invoke("bias", frames, "-o", tmp_path / name, "--preview",
                    tmp_path / os.fsdecode(b"p\xe9.png"), "-q")
    assert result.exit_code == 0, result.output
    made = set(os.listdir(os.fsencode(tmp_path)))
    assert {b"lat\xe9.tif", b".lat\xe9.tif.plenocli.json", b"p\xe9.png"} <= made
    result = invoke("bias", tmp_path / name, "-o", tmp_path / "again.tif", "-q")
    assert result.exit_code == 1 and "is a `plenocli bias` output" in result.output  # read back


def test_an_input_that_is_a_loop_or_a_dangling_link_says_so(tmp_path):
    # audit 10 I1's neighbours: a looping or dangling input link was "no such file"
    (tmp_path / "l.tif").symlink_to("l.tif")
    (tmp_path / "d.tif").symlink_to("nowhere.tif")
    loop = invoke("bias", tmp_path / "l.tif", "-o", tmp_path / "v.tif")
    assert loop.exit_code == 1 and "a symbolic link loop" in one_line(loop)
    dangling = invoke("info", tmp_path / "d.tif")
    assert dangling.exit_code == 1
    assert "a symbolic link to nowhere.tif, which does not exist" in one_line(dangling)


def test_a_file_name_that_is_not_utf8_is_shown_as_a_terminal_shows_it(tmp_path, frames):
    """audit 24a M1: the bytes of a name that are not UTF-8 were shown as Python's surrogate
    escape (bad\\udcffname); a terminal's replacement character is what `ls` users see."""
    name = os.fsdecode(b"bad\xffname.tif")
    result = invoke("bias", tmp_path / name, "-o", tmp_path / "b.tif")
    assert result.exit_code == 1 and "bad\ufffdname.tif" in result.output, result.output
    assert "\\udcff" not in result.output.encode("unicode_escape").decode()
