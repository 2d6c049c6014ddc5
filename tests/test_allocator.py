import ctypes.util
import os
import subprocess
import sys
import textwrap

import pytest

from unps.allocator import keep_freed_memory


def glibc() -> bool:
    try:
        return "glibc" in (os.confstr("CS_GNU_LIBC_VERSION") or "").lower()
    except (ValueError, OSError, AttributeError):   # not a glibc system
        return False


@pytest.mark.skipif(not glibc(), reason="mallopt is glibc's")
def test_glibc_accepts_the_settings():
    assert ctypes.util.find_library("c") is not None
    assert keep_freed_memory() is True
    assert keep_freed_memory() is True   # idempotent: a second fit in one process


@pytest.mark.skipif(not glibc(), reason="mallopt is glibc's")
def test_a_block_beyond_any_mmap_threshold_comes_from_the_heap():
    """A 256 MiB tensor is mapped on its own before, served from the heap after (in a fresh
    process: the setting is the process's)."""
    script = textwrap.dedent("""
        import ctypes, torch
        from unps.allocator import keep_freed_memory

        class MallInfo2(ctypes.Structure):
            _fields_ = [(name, ctypes.c_size_t) for name in
                        ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                         "uordblks", "fordblks", "keepcost")]

        mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
        mallinfo2.restype = MallInfo2
        size = 256 << 20
        before = torch.empty(size, dtype=torch.uint8)
        mapped_before = mallinfo2().hblkhd
        keep_freed_memory()
        after = torch.empty(size, dtype=torch.uint8)
        print(mapped_before >= size, mallinfo2().hblkhd == mapped_before, mallinfo2().arena >= size)
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["True", "True", "True"]


def test_a_no_op_elsewhere(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert keep_freed_memory() is False
