"""Byte transports between ground stations and the vehicle: real UDP, and an in-process lockstep queue.

Both carry real MAVLink bytes; neither parses them. The lockstep transport delivers at simulated times, so a
scripted ground station and the vehicle can run as fast as the machine allows and stay deterministic.
"""

from __future__ import annotations

import contextlib
import heapq
import select
import socket
from collections.abc import Callable, Collection

Address = tuple[str, int]


class UdpTransport:
    """One UDP socket. ``udpin``: bound, answers whoever talks to it; ``udpout``: also sends to fixed peers
    (as SITLs send to 127.0.0.1:14550 and :14540 before anyone has spoken).

    The table of learned peers is bounded (``max_peers``), so a stranger cycling through source ports could push
    everyone else out of it. ``pinned`` says which addresses must never go: the vehicle passes its owner's (and a
    signed station's), so the transport stays free of lease logic. Strangers share what is left of the table, the
    oldest unpinned address giving way, and a pinned address is always sent to, even if it was never learned.
    """

    def __init__(self, bind: Address = ("127.0.0.1", 0), peers: tuple[Address, ...] = (),
                 max_peers: int = 16, pinned: Callable[[], Collection[Address]] | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(bind)
        self.sock.setblocking(False)
        self.fixed = list(peers)
        self.learned: list[Address] = []
        self.max_peers = max_peers
        self.pinned = pinned

    @property
    def address(self) -> Address:
        host, port = self.sock.getsockname()
        return host, port

    def receive(self, max_packets: int = 256) -> list[tuple[bytes, Address]]:
        out = []
        for _ in range(max_packets):
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # ICMP port unreachable from a peer that went away
                continue
            if addr not in self.fixed and addr not in self.learned:
                self._learn(addr)
            out.append((data, addr))
        return out

    def ready(self, timeout: float) -> bool:
        """Whether a datagram can be read within ``timeout`` seconds (a loop serving its link between ticks)."""
        try:
            readable, _, _ = select.select([self.sock], [], [], max(0.0, timeout))
        except (OSError, ValueError):  # closed under us: nothing will come
            return False
        return bool(readable)

    def _learn(self, addr: Address) -> None:
        """Add a peer; when the table is full the oldest address that is not pinned makes room."""
        if len(self.learned) >= self.max_peers:
            keep = set(self.pinned()) if self.pinned is not None else set()
            victim = next((i for i, a in enumerate(self.learned) if a not in keep), None)
            if victim is None:
                return  # every slot holds a pinned peer: a stranger waits
            del self.learned[victim]
        self.learned.append(addr)

    def send(self, data: bytes, to: Address | None = None) -> None:
        if to:
            targets = [to]
        else:
            targets = [*self.fixed, *self.learned]
            if self.pinned is not None:
                targets += [a for a in self.pinned() if a not in targets]
        for addr in targets:
            # nobody listening there (yet) is fine: UDP telemetry is fire and forget
            with contextlib.suppress(OSError):
                self.sock.sendto(data, addr)

    def close(self) -> None:
        self.sock.close()


class LockstepBus:
    """Named endpoints exchanging bytes at simulated times. A delay (and whether a packet arrives at all) is
    decided by the sender's caller, e.g. the radio model; equal times keep send order.

    One heap per destination, of plain (time, order, source, bytes) tuples: a receiver pops only its own packets
    (one shared heap made every receive pop and re-push everyone else's, on every tick)."""

    def __init__(self) -> None:
        self._queues: dict[str, list[tuple[float, int, str, bytes]]] = {}
        self._seq = 0
        self.delivered = 0

    def send(self, src: str, dst: str, data: bytes, at: float) -> None:
        self._seq += 1
        q = self._queues.get(dst)
        if q is None:
            q = self._queues[dst] = []
        heapq.heappush(q, (at, self._seq, src, data))

    def inbox(self, dst: str) -> list[tuple[float, int, str, bytes]]:
        """The live queue of ``dst``, a heap whose head ``[0][0]`` is the earliest arrival time: a lockstep loop
        looks at it to skip ``receive`` on the many ticks nothing is due. Read it only; ``send`` and ``receive``
        change it."""
        q = self._queues.get(dst)
        if q is None:
            q = self._queues[dst] = []
        return q

    def receive(self, dst: str, now: float) -> list[tuple[bytes, str]]:
        """Every packet for ``dst`` due by ``now``, in time order, equal times in send order."""
        q = self._queues.get(dst)
        if not q or q[0][0] > now:
            return []
        due = []
        while q and q[0][0] <= now:
            _, _, src, data = heapq.heappop(q)
            due.append((data, src))
        self.delivered += len(due)
        return due

    def pending(self) -> int:
        return sum(len(q) for q in self._queues.values())
