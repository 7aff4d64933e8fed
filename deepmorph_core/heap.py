"""Keep the memory a training step frees for the next step, instead of handing it back.

A training step on the CPU allocates and frees the same large tensors every step (a 32-image
batch of decoder activations at 96 px is tens of megabytes). glibc's allocator serves blocks
above its mmap threshold (128 KiB, rising to at most 32 MiB) with fresh ``mmap`` calls and
returns them with ``munmap``, and trims the heap's top whenever 128 KiB are free there; either
way the next step touches new pages, and the kernel zero-fills each one on a page fault. Kept
in the heap, a ``--pixels 200`` stage-2 step on one thread took 0.86x as long, and on two the
same (``docs/design-notes.md``, *Speed*).

:func:`keep_freed_memory` sets three of glibc's ``mallopt`` parameters for the whole process:
blocks up to 1 GiB come from the heap, a freed heap top is kept, and the heap grows 256 MiB at a
time. The process keeps its peak heap until it exits, which suits a training command and not a
long-running server, so only training calls it. Elsewhere than glibc (macOS, Windows, musl) it
does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import cache

# mallopt(3) parameter numbers, from glibc's <malloc.h>
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_THRESHOLD = -3

HEAP_BLOCKS_UP_TO = 1 << 30  # served from the heap, not mmap
HEAP_GROWTH = 256 << 20  # extra heap asked of the kernel each time the heap grows
NEVER_TRIM = 2**31 - 1  # free bytes at the heap's top before it is handed back (int max)


@cache
def keep_freed_memory() -> bool:
    """Keep freed memory in this process's heap for reuse (glibc only); whether it was set.

    Called once per process: later calls return the first call's answer."""
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    settings = ((M_MMAP_THRESHOLD, HEAP_BLOCKS_UP_TO), (M_TRIM_THRESHOLD, NEVER_TRIM), (M_TOP_PAD, HEAP_GROWTH))
    return all(mallopt(param, value) == 1 for param, value in settings)


__all__ = ["keep_freed_memory"]
