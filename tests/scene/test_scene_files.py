"""Scene files that cannot be a scene (issue 11, section 5): binary, UTF-16, a Latin-1 byte, a
directory, a FIFO, an unreadable file, broken TOML - each one line naming the path and the
reason, not a traceback (and not a hang); an empty file is the default scene."""

import os
import pathlib
import random
import subprocess
import sys
import threading

import pytest

from fxflex.errors import SceneError
from fxflex.scene import Scene, load_scene

SCENE = "[geometry]\n# twist of the blade\nlength = 2.0\n"


def _error(path) -> SceneError:
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    message = str(exc.value)
    assert exc.value.key == "--scene" and "\n" not in message and "\r" not in message, message
    return exc.value


def test_random_bytes_name_the_file_and_the_first_bad_byte(tmp_path):
    """``head -c 2000 /dev/urandom > s.toml``, with a fixed seed."""
    path = tmp_path / "s.toml"
    path.write_bytes(random.Random(11).randbytes(2000))
    message = str(_error(path))
    assert str(path) in message and "is not UTF-8 text (byte 0x" in message


def test_utf16_with_byte_order_mark(tmp_path):
    path = tmp_path / "s.toml"
    path.write_bytes(SCENE.encode("utf-16"))
    message = str(_error(path))
    assert str(path) in message and "UTF-16" in message and "allowed: UTF-8" in message


def test_latin1_byte_gives_its_offset(tmp_path):
    path = tmp_path / "s.toml"
    raw = SCENE.replace("twist", "tw\u00efst").encode("latin-1")
    path.write_bytes(raw)
    message = str(_error(path))
    assert f"byte 0xef at offset {raw.index(0xef)}" in message and str(path) in message


def test_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "s.toml"
    path.write_bytes(SCENE.encode("utf-8-sig"))
    assert load_scene(path).geometry.length == 2.0


def test_empty_file_is_the_default_scene(tmp_path):
    path = tmp_path / "s.toml"
    path.write_bytes(b"")
    assert load_scene(path) == Scene()


def test_directory(tmp_path):
    assert f"{tmp_path} is a directory" in str(_error(tmp_path))


def test_fifo_is_refused_without_blocking(tmp_path):
    """Opening a FIFO with no writer blocks for ever; it is refused before it is opened."""
    path = tmp_path / "s.toml"
    os.mkfifo(path)
    outcome = []

    def load():
        try:
            load_scene(path)
        except SceneError as exc:
            outcome.append(str(exc))

    worker = threading.Thread(target=load, daemon=True)
    worker.start()
    worker.join(timeout=20)
    if worker.is_alive():               # unblock the reader so the test process can end
        with open(path, "wb"):
            pass
        pytest.fail("load_scene blocked on a FIFO")
    assert outcome and "not a regular file" in outcome[0]


def test_unreadable_file(tmp_path, monkeypatch):
    """A file without read permission names the file and the reason (as root, who reads any
    file, the refusal is simulated)."""
    path = tmp_path / "s.toml"
    path.write_text(SCENE)
    path.chmod(0)
    if os.access(path, os.R_OK):

        def refuse(self):
            raise PermissionError(13, "Permission denied", str(self))

        monkeypatch.setattr(pathlib.Path, "read_bytes", refuse)
    assert f"cannot read {path}: Permission denied" in str(_error(path))


def test_toml_syntax_error_names_file_line_and_column(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[geometry\nlength = 1\n")
    message = str(_error(path))
    assert f"{path} is not valid TOML" in message and "line 1" in message


def test_path_with_a_newline_stays_one_line(tmp_path):
    path = tmp_path / "a\nb.toml"
    path.write_bytes(b"\xff\x00")
    assert repr(str(path)) in str(_error(path))


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
def test_cli_prints_one_line_and_exits_2(tmp_path):
    scene = tmp_path / "in" / "s.toml"
    scene.parent.mkdir()
    scene.write_bytes(random.Random(5).randbytes(2000))
    out = tmp_path / "out"
    out.mkdir()
    r = subprocess.run([sys.executable, "-m", "fxflex", "info", "--scene", str(scene)],
                       capture_output=True, text=True, cwd=out, timeout=300)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and r.stdout == "" and list(out.iterdir()) == []
    assert len(lines) == 1 and lines[0].startswith(f"fxflex: error: --scene: {scene} is not "
                                                   "UTF-8 text"), r.stderr
