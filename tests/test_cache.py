"""The disk cache (fxflex.cache): keys, atomic entries, bypass, the ``fxflex cache`` command."""

import json
import subprocess
import sys

import numpy as np
import pytest

from fxflex import cache

pytestmark = pytest.mark.serial


def test_entry_round_trip_leaves_no_temporary_file(folder):
    arrays = {"a": np.arange(5.0), "b": np.array(3.5), "c": np.eye(2, dtype=bool)}
    path = cache.save("modes", "k1", arrays)
    assert path == folder / "modes" / "k1.npz" and path.exists()
    back = cache.load("modes", "k1")
    assert set(back) == set(arrays) and all(np.array_equal(back[k], arrays[k]) for k in arrays)
    assert back["c"].dtype == bool
    assert [p.name for p in (folder / "modes").iterdir()] == ["k1.npz"]
    assert cache.load("modes", "other") is None


def test_unreadable_entry_is_a_miss(folder):
    (folder / "modes").mkdir()
    (folder / "modes" / "k1.npz").write_bytes(b"not a zip archive")
    assert cache.load("modes", "k1") is None


def test_keys_follow_every_part():
    parts = {"mesh": "abc", "count": 30, "material": {"E": 210e9}, "code": "x"}
    key = cache.entry_key(parts)
    assert key == cache.entry_key(dict(reversed(list(parts.items()))))     # order-free
    for name, value in (("mesh", "abd"), ("count", 31), ("material", {"E": 200e9}),
                        ("code", "y")):
        assert cache.entry_key({**parts, name: value}) != key, name


def test_code_version_is_the_source_of_the_named_modules():
    a = cache.code_version("fxflex.solid.cms")
    assert a == cache.code_version("fxflex.solid.cms")
    assert a != cache.code_version("fxflex.solid.cms", "fxflex.solid.forms")


def test_no_cache_bypasses_reads_and_writes(folder, monkeypatch):
    cache.save("modes", "k1", {"a": np.zeros(2)})
    monkeypatch.setenv("FXFLEX_NO_CACHE", "1")
    assert not cache.enabled() and not cache.enabled("modes")
    assert cache.load("modes", "k1") is None and cache.save("reduced", "k2", {"a": 1}) is None
    assert not (folder / "reduced").exists()
    monkeypatch.setenv("FXFLEX_NO_CACHE", "modes,reduced")
    assert not cache.enabled("modes") and cache.enabled("meshes")
    monkeypatch.setenv("FXFLEX_NO_CACHE", "0")
    assert cache.enabled() and cache.load("modes", "k1") is not None
    with cache.bypass("modes"):
        assert cache.load("modes", "k1") is None and cache.enabled("tlf-invariants")
    assert cache.enabled("modes")


def test_bypass_leaves_the_environment_alone(folder, monkeypatch):
    """The in-process override: enabled() is False inside the block, os.environ is the same
    object with the same contents, and FXFLEX_NO_CACHE still bars what it names."""
    import os
    import threading

    cache.save("modes", "k1", {"a": np.zeros(2)})
    before = dict(os.environ)
    with cache.bypass():
        assert dict(os.environ) == before and "FXFLEX_NO_CACHE" not in os.environ
        assert not cache.enabled() and not any(cache.enabled(k) for k in cache.KINDS)
        assert cache.load("modes", "k1") is None
        assert cache.save("reduced", "k2", {"a": 1}) is None and not (folder / "reduced").exists()
        seen = []                   # another thread has its own context: not bypassed
        thread = threading.Thread(target=lambda: seen.append(cache.enabled("modes")))
        thread.start()
        thread.join()
        assert seen == [True]
    assert dict(os.environ) == before and cache.enabled() and cache.load("modes", "k1") is not None
    with cache.bypass("modes"):
        assert not cache.enabled("modes") and cache.enabled("reduced") and not cache.enabled()
        with cache.bypass("reduced"):           # nested blocks add up
            assert not cache.enabled("modes") and not cache.enabled("reduced")
            assert cache.enabled("meshes")
        assert not cache.enabled("modes") and cache.enabled("reduced")
    with pytest.raises(RuntimeError), cache.bypass("modes"):    # an exception ends it too
        raise RuntimeError
    assert cache.enabled("modes")
    monkeypatch.setenv("FXFLEX_NO_CACHE", "meshes")     # the environment still counts inside
    with cache.bypass("modes"):
        assert not cache.enabled("meshes") and not cache.enabled("modes")
        assert cache.enabled("reduced") and os.environ["FXFLEX_NO_CACHE"] == "meshes"
    with pytest.raises(ValueError, match="unknown kind"):
        with cache.bypass("mode"):
            pass


def test_bypass_is_not_inherited_by_child_processes(folder):
    """A child process (the CLI) sees the environment, not this process's bypass."""
    code = "from fxflex import cache; print(cache.enabled('modes'))"
    with cache.bypass("modes"):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "True"


def test_cache_command_lists_and_clears(folder):
    cache.save("modes", "k1", {"a": np.zeros(1000)})
    cache.save("reduced", "k2", {"a": np.zeros(10)})

    def fx(*args):
        r = subprocess.run([sys.executable, "-m", "fxflex", "cache", *args, "--json"],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    info = fx("info")
    assert info["cache_dir"] == str(folder) and info["kinds"]["modes"]["files"] == 1
    assert info["kinds"]["modes"]["bytes"] > 8000 and info["scene_hash"]
    out = fx("clear", "--kind", "modes")
    assert out["removed"] == {"modes": info["kinds"]["modes"]}
    assert not (folder / "modes").exists() and (folder / "reduced" / "k2.npz").exists()
    assert fx("clear")["removed"]["reduced"]["files"] == 1
    assert not (folder / "reduced").exists()


def test_cache_command_bad_input_is_one_line(folder):
    r = subprocess.run([sys.executable, "-m", "fxflex", "cache", "info", "--kind", "modes"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().startswith("fxflex: error: --kind") and len(r.stderr.splitlines()) == 1
