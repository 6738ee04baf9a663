"""Progress bars over points that say when they are compiling."""

from __future__ import annotations


class PointProgress:
    """A tqdm bar counting points [pt] of ``total``, labelled ``desc (compiling)`` until the
    first points are done (``initial``: those done before, a resumed study's; the first
    compiled call pays the tracing and the compilation, or
    reads them back from the persistent cache), then ``desc``.  A context manager; disabled
    (and free) when ``enabled`` is false."""

    def __init__(self, total: int, desc: str, enabled: bool, initial: int = 0):
        from tqdm.auto import tqdm

        self.desc = desc
        self.started = False
        self.bar = tqdm(total=int(total), initial=int(initial), desc=f"{desc} (compiling)",
                        unit="pt", disable=not enabled)

    def update(self, points: int) -> None:
        """``points`` more are done."""
        if not self.started:
            self.bar.set_description(self.desc)
            self.started = True
        self.bar.update(int(points))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.bar.close()
        return False
