"""The lockstep doorbell, mapped from Python.

The orchestrator wakes the processes due at a tick through one shared-memory
segment per run (`services/runtime/src/doorbell.rs` says how): a slot per
process, each on a cache line of its own, holding the counter of its
wake-ups, the last one it finished, and the tick it is for. A process sleeps
in FUTEX_WAIT on its counter (or its group's gate), steps, stores the
wake-up it finished, decrements the tick's count of processes stepping, and
the one that brings it to zero wakes the orchestrator (FUTEX_WAKE on done's
counter). The layout comes from `contract.py`, generated from the Rust
type; the read-modify-writes are atomic instructions (the `atomics`
package), as in Rust.
"""

from __future__ import annotations

import ctypes
import errno
import mmap
import os
from typing import NamedTuple, Optional

import atomics

from . import contract as c

_SYS_FUTEX = {"x86_64": 202, "aarch64": 98}.get(os.uname().machine)
_FUTEX_WAIT = 0
_FUTEX_WAKE = 1
_libc = ctypes.CDLL(None, use_errno=True)
_libc.syscall.restype = ctypes.c_long


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class Rung(NamedTuple):
    """The tick a wake-up is for."""

    tick: int
    sim_time_ns: int
    last: bool


class DoorbellError(RuntimeError):
    """The doorbell could not be mapped or is too small for the run."""


class Doorbell:
    """One process's view of the run's doorbell."""

    def __init__(self, run_id: str, processes: int):
        if _SYS_FUTEX is None:
            raise DoorbellError(f"no futex system call number known for {os.uname().machine}")
        name = c.DOORBELL.format(run_id=run_id)
        path = f"/dev/shm/{name}"
        try:
            fd = os.open(path, os.O_RDWR)
        except OSError as e:
            raise DoorbellError(f"cannot open the lockstep doorbell {path}: {e}") from e
        try:
            size = os.fstat(fd).st_size
            self._map = mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        finally:
            os.close(fd)
        found = size // c.SLOT_BYTES - c.EXTRA_SLOTS
        if found < processes:
            raise DoorbellError(f"{path} holds {found} counters, the run has {processes} processes")
        self._view = memoryview(self._map)
        self._base = ctypes.addressof(ctypes.c_char.from_buffer(self._map))
        self._slots = processes

    def close(self) -> None:
        self._view.release()
        try:
            self._map.close()
        except BufferError:
            pass  # a ctypes view still alive; the mapping goes with the process

    def _at(self, slot: int, field: str) -> int:
        return slot * c.SLOT_BYTES + c.SLOT_FIELDS[field]

    def _u32(self, slot: int, field: str) -> int:
        return ctypes.c_uint32.from_address(self._base + self._at(slot, field)).value

    def _u64(self, slot: int, field: str) -> int:
        return ctypes.c_uint64.from_address(self._base + self._at(slot, field)).value

    def _atomic(self, slot: int, field: str):
        at = self._at(slot, field)
        return atomics.atomicview(buffer=self._view[at : at + 4], atype=atomics.UINT)

    def _futex(self, slot: int, field: str, op: int, val: int, timeout_s: Optional[float]) -> None:
        ts = None
        if timeout_s is not None:
            ts = _Timespec(int(timeout_s), int((timeout_s % 1.0) * 1e9))
        r = _libc.syscall(
            _SYS_FUTEX,
            ctypes.c_void_p(self._base + self._at(slot, field)),
            ctypes.c_int(op),
            ctypes.c_uint32(val),
            ctypes.byref(ts) if ts is not None else None,
            None,
            ctypes.c_uint32(0),
        )
        if r < 0 and ctypes.get_errno() not in (errno.EAGAIN, errno.EINTR, errno.ETIMEDOUT):
            raise OSError(ctypes.get_errno(), "futex")

    def seq(self, i: int) -> int:
        """Wake-ups rung to process `i` so far."""
        return self._u32(i, "seq")

    def rung(self, i: int) -> Rung:
        """The tick of process `i`'s latest wake-up."""
        return Rung(self._u64(i, "tick"), self._u64(i, "sim_time_ns"), self._u32(i, "last") != 0)

    def _gate(self, i: int) -> tuple[int, str]:
        g = self._u32(i, "group")
        if g == 0:
            return i, "seq"
        return min(g - 1, self._slots - 1), "gate"

    def wait(self, i: int, seen: int, timeout_s: float) -> Optional[int]:
        """Sleeps until process `i`'s counter differs from `seen` (or the
        timeout, or a signal); the counter if it moved."""
        slot, field = self._gate(i)
        g = self._u32(slot, field)
        now = self.seq(i)
        if now != seen:
            return now
        self._futex(slot, field, _FUTEX_WAIT, g, timeout_s)
        now = self.seq(i)
        return now if now != seen else None

    def finished(self, i: int, seq: int) -> bool:
        """Records that process `i` finished wake-up `seq`; true when it must
        wake the orchestrator (it was the tick's last, or its step was not
        counted)."""
        with self._atomic(i, "done") as done:
            done.store(seq)
        if self._u32(i, "counted") == 0:
            return True
        with self._atomic(self._slots, "seq") as stepping:
            while True:
                n = stepping.load()
                if n == 0:
                    return False
                if stepping.cmpxchg_weak(n, n - 1).success:
                    return n == 1

    def notify_done(self) -> None:
        """Wakes the orchestrator: done's counter moves."""
        slot = self._slots + 1
        with self._atomic(slot, "seq") as done:
            done.fetch_add(1)
        self._futex(slot, "seq", _FUTEX_WAKE, 1, None)
