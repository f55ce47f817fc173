"""Take part in a shoal run from Python.

    import shoal_node as sn
    from shoal_node import msgs

    node = sn.Node.from_args()
    nav_in = node.subscriber("nav")
    setpoint_out = node.publisher("setpoint")
    for step in node.steps():
        nav = nav_in.latest(step)
        ...
        setpoint_out.publish(msgs.Setpoint(), step, sn.Origin.of(nav.header))

`msgs` holds every sample type of the run as a ctypes structure, generated
from the Rust types (`contract.py`); `Node` is the process's place in the
run (see `node.py` for the contract it keeps).
"""

import ctypes as _ctypes

from . import contract as msgs
from .node import Histogram, Node, Origin, Publisher, Step, Subscriber, non_finite_field

__all__ = ["msgs", "Node", "Origin", "Step", "Publisher", "Subscriber", "Histogram", "non_finite_field", "text"]


def text(field) -> str:
    """A NUL-padded fixed-size text field (`ProcessStats.vehicle`, ...) as str."""
    raw = bytes(field)
    return raw.split(b"\0", 1)[0].decode("ascii", "replace")


def _check_layout() -> None:
    """Every generated sample type has its Rust size (a ctypes layout that
    differed would be refused by iceoryx2 only when a port opens)."""
    for cls, _ in list(msgs.CHANNELS.values()) + list(msgs.RUN_CHANNELS.values()):
        if _ctypes.sizeof(cls) != cls.SIZE or _ctypes.alignment(cls) != 8:
            raise ImportError(f"shoal_node: {cls.__name__} is {_ctypes.sizeof(cls)} bytes, the Rust type {cls.SIZE}")


_check_layout()
