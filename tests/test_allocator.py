import ctypes.util
import os
import sys

import pytest

from unps.allocator import keep_freed_memory


def glibc() -> bool:
    try:
        return "glibc" in (os.confstr("CS_GNU_LIBC_VERSION") or "").lower()
    except (ValueError, OSError, AttributeError):   # not a glibc system
        return False


@pytest.mark.skipif(not glibc(), reason="mallopt is glibc's")
def test_glibc_accepts_the_thresholds():
    assert ctypes.util.find_library("c") is not None
    assert keep_freed_memory() is True
    assert keep_freed_memory() is True   # idempotent: a second fit in one process


def test_a_no_op_elsewhere(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert keep_freed_memory() is False
