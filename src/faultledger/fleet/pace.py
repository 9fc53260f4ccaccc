"""How many records a robot puts in its next batch (docs/fleet.md, "Batch size").

Each answer should come back in about ``ANSWER_SEC``: a robot catching up after a night away
must not keep the central busy for seconds per batch while twenty others wait behind it, and
a robot alone should still send full batches. So the next batch holds what the central took
in ``ANSWER_SEC`` at the pace of the last answers (records / seconds from sending to the
answer), at most twice and at least half the last size, between ``FEWEST`` and the protocol's
1,000. When every robot does this, each one's share of the central's pace sets its size: 20
robots on a central taking 40,000 records/s send about 300 records a batch, answered in about
0.15 s; one robot alone sends 1,000 from its third batch on.
"""

from __future__ import annotations

ANSWER_SEC = 0.15
FEWEST = 50


class BatchPace:
    """The next batch's size, from how fast the central answered the last ones."""

    def __init__(self, most: int, answer_sec: float = ANSWER_SEC, fewest: int = FEWEST) -> None:
        self.most = most
        self.fewest = min(fewest, most)
        self.answer_sec = answer_sec
        self.size = max(self.fewest, most // 4)
        """Records for the next batch: a quarter of the most to begin with (twenty robots
        starting at once each wait for the others' first batches), doubling while the
        answers come fast."""

    def answered(self, records: int, seconds: float) -> None:
        """A batch of ``records`` was answered ``seconds`` after it was sent."""
        if records <= 0:
            return
        wanted = records / max(seconds, 1e-6) * self.answer_sec
        self.size = int(max(self.fewest, min(self.most, self.size * 2,
                                             max(self.size / 2, wanted))))
