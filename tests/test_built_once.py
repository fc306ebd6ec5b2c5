"""A certificate is built once per process (``lfc.filters.base.built_once``) and,
when it took long to build, kept on disk for the next process: read back bit for
bit, rebuilt when damaged, keyed by every digit of its arguments."""

import os

import numpy as np
import pytest

import lfc
import lfc.filters.base as base
import lfc.filters.certified as certified

ROBUST = {"method": "certified", "noise_std": (1e-4, 1e-3)}   # on an estimate: its ellipsoid


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder, an empty memo, and every build stored."""
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(base, "STORE_AFTER", 0.0)
    monkeypatch.setattr(base, "_BUILT", base.OrderedDict())
    return tmp_path / "built"


def _no_build(*args, **kwargs):
    raise AssertionError("built again instead of read from the disk")


def test_a_stored_certificate_is_read_back_bit_for_bit_without_building_it(cache, monkeypatch):
    first = lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    assert len(list(cache.glob("*.json"))) == 1
    base.clear_built()                               # a new process: only the disk is left
    monkeypatch.setattr(certified.CertifiedSet, "__init__", _no_build)
    again = lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    assert again.cert is not first.cert
    assert again.data.tobytes() == first.data.tobytes()
    x = np.array([0.01, 0.0, 0.002, 0.002, 0.01])
    assert again.filter(x, 0.3)[0] == first.filter(x, 0.3)[0]


def test_a_damaged_stored_certificate_warns_and_is_built_again(cache):
    first = lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    (path,) = cache.glob("*.json")
    text = path.read_text()
    path.write_text(text[:len(text) // 2] + "x" + text[len(text) // 2 + 1:])
    base.clear_built()
    with pytest.warns(RuntimeWarning, match="damaged cache file"):
        again = lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    assert again.data.tobytes() == first.data.tobytes()
    base.clear_built()                               # and stored again, whole
    assert lfc.SafetyFilter(lfc.LFCParams(), **ROBUST).data.tobytes() == first.data.tobytes()


def test_other_arguments_or_another_blas_kernel_are_other_files(cache, monkeypatch):
    lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    lfc.SafetyFilter(lfc.LFCParams(), **{**ROBUST, "noise_std": (1e-4, 1.0000000001e-3)})
    asked = os.environ.get("OPENBLAS_CORETYPE", "")         # another one than this run's
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Sandybridge" if asked == "Haswell" else "Haswell")
    base.clear_built()
    lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    assert len(list(cache.glob("*.json"))) == 3


def test_a_quick_build_is_not_stored(tmp_path, monkeypatch):
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(base, "_BUILT", base.OrderedDict())
    assert base.built_once(lambda: [1.0], "quick", store=True) == [1.0]
    assert not list(tmp_path.rglob("*.json"))


def test_the_key_holds_every_digit_and_every_element_of_an_array(monkeypatch):
    monkeypatch.setattr(base, "_BUILT", base.OrderedDict())
    a = np.linspace(0.0, 1.0, 5000)
    b = a.copy()
    b[2500] += 1e-15
    made = [base.built_once(object, "arrays", x) for x in (a, b, a.copy())]
    assert made[0] is not made[1] and made[2] is made[0]
    assert base.built_once(object, 0.1234567891) is not base.built_once(object, 0.1234567892)


def test_the_stored_folder_keeps_the_newest_within_its_limit(cache, monkeypatch):
    lfc.SafetyFilter(lfc.LFCParams(), **ROBUST)
    (older,) = cache.glob("*.json")
    monkeypatch.setattr(base, "STORE_LIMIT", 1.5 * older.stat().st_size)
    lfc.SafetyFilter(lfc.LFCParams(), **{**ROBUST, "margin": 0.1})
    (newest,) = cache.glob("*.json")
    assert newest != older


def test_a_value_that_cannot_be_stored_warns_and_is_still_returned(cache):
    with pytest.warns(RuntimeWarning, match="cannot store"):
        made = base.built_once(lambda: (lambda: 1.0), "unpicklable", store=True)
    assert made() == 1.0 and not list(cache.glob("*.json"))


def test_the_key_names_the_installed_numerical_packages():
    from lfc._files import installed
    assert all(name in installed() for name in ("numpy", "scipy", "numba"))


def test_the_largest_load_bound_is_kept_and_its_options_are_in_the_key(cache, monkeypatch):
    """``largest_load_bound`` (a bisection of constructions) is read back in a new
    process without constructing anything; other options are another answer."""
    p, r = lfc.LFCParams(), lfc.RelaySettings()
    first = certified.largest_load_bound(p, r, tol=0.01, load_kind="steps")
    base.clear_built()
    monkeypatch.setattr(certified.CertifiedSet, "__init__", _no_build)
    assert certified.largest_load_bound(p, r, tol=0.01, load_kind="steps") == first
    with pytest.raises(AssertionError, match="built again"):
        certified.largest_load_bound(p, r, tol=0.01)              # the default load_kind
