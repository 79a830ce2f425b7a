"""The patent's FIG. 2-3 sequence driven through the real lease code, printed as a timeline.

It is the smallest honest demonstration of the rules: nothing is simulated but time and the operator's messages.
"""

from __future__ import annotations

from collections.abc import Callable

from vehicle.lease import ExpireReason, LeaseBook, LeaseConfig, LeaseId, Outcome, ServiceBlock

GCS = 255


def run(echo: Callable[[str], None] = print) -> LeaseBook:
    plan = (ServiceBlock("RETURN_TO_LINK 50 m"), ServiceBlock("LOITER 60 s"), ServiceBlock("RETURN_TO_LAUNCH"))
    book = LeaseBook(config=LeaseConfig(link_timeout=3.0, regain_s=1.0), plan=plan)

    def show(t: float, what: str, out: Outcome | None = None) -> None:
        nonlocal book
        if out is not None:
            book = out.book
            for ev in out.events:
                what += f"\n{'':>9}event: {ev.describe()}"
        seq = " ".join(
            f"[{book.epoch},{x.index}]{'*' if k == 0 else ''}{x.holder.name[0]}" for k, x in enumerate(book.leases))
        echo(f"t={t:6.2f}  {what}\n{'':>9}leases: {seq or '(no root)'}")

    echo("returnlink lease timeline (patent FIG. 2-3); * = current, O = operator, R = return service\n")
    show(0.0, "operator 255 acquires the root lease", book.acquire(GCS, 190, 0.0, seed=2022))
    e = book.epoch
    for t in (1.0, 2.0, 3.0, 4.0):
        book = book.heard(GCS, t)
        chk = book.check(GCS, LeaseId(e, (0, 0)))
        show(t, f"teleop under [{e},0,0]: {chk.verdict.value}", book.tick(t))
    show(4.5, "operator drives into the tunnel; last message heard at t=4.0")
    for t in (5.0, 6.0, 6.98):
        show(t, "silence", book.tick(t))
    show(7.0, "LNK_TIMEOUT of silence reached", book.tick(7.0))
    ret = book.current_id
    book, nav = book.issue_sublease(ret)
    for n in range(2):
        book, seg = book.issue_sublease(nav)
        show(7.0 + n, f"return service drives segment {seg}")
    stale = book.check(GCS, LeaseId(e, (0,)))
    show(8.5, f"a delayed teleop packet under [{e},0] arrives: {stale.verdict.value} ({stale.reason.value})")
    for t in (12.0, 12.5, 13.0):
        book = book.heard(GCS, t)
        show(t, "operator heard again", book.tick(t))
    out, chk = book.claim(GCS, e, -1, 14.0)
    show(14.0, f"operator resumes: claims {chk.lease}", out)
    out, chk = book.expire(GCS, e, book.current.index, 20.0)
    show(20.0, "operator presses RTL (explicit expire)", out)
    for reason in (ExpireReason.COMPLETED, ExpireReason.COMPLETED):
        show(30.0, f"return service reports {reason.name}", book.finish(book.current.index, reason, 30.0))
    return book


if __name__ == "__main__":
    run()
