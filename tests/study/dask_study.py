"""The Dask half of tests/study/test_study.py, run as a script in a process of its own
(Dask's threads and worker processes kept out of the test process):
``python dask_study.py OUT``.

On a two-worker ``LocalCluster``, a 12-chunk study whose question logs every chunk it
starts and finishes (``OUT/log.txt``), stored in ``OUT/s.zarr``; one worker is killed
(SIGKILL) in the middle of a chunk once another chunk is done.

Writes ``OUT/report.json``: the chunks computed, the number of workers, the killed process
id.
"""

from __future__ import annotations

import json
import os
import pathlib
import sys
import threading
import time

import numpy as np


def main(out):
    from distributed import Client, LocalCluster
    from study_scene import KT, QUESTION, Counting, log_lines, tmd_system

    import absorber_jax as aj

    out = pathlib.Path(out)
    log = str(out / "log.txt")
    report, killed = {}, []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as lc, Client(lc) as client:
        pids = client.run(os.getpid)
        report["workers"] = len(pids)

        def kill_one():
            # once a chunk is done, kill a worker in the middle of its next one
            t0 = time.time()
            while time.time() - t0 < 120:
                done = [int(line.split()[0]) for line in log_lines(log)]
                busy = [int(line.split()[0]) for line in log_lines(log + ".start")]
                for pid in pids.values():
                    if done and busy.count(pid) > done.count(pid):
                        os.kill(pid, 9)
                        killed.append(pid)
                        return
                time.sleep(0.02)

        th = threading.Thread(target=kill_one)
        th.start()
        grid = aj.Grid({"tmd1.k": KT * np.linspace(0.9, 1.1, 12)})
        res = aj.study(tmd_system(), grid, Counting(QUESTION, log, pause=0.5),
                       store=out / "s.zarr", chunk=1, client=client)
        th.join()
    report["killed"] = killed[0] if killed else None
    report["computed"] = [int(c) for c in res.computed]
    (out / "report.json").write_text(json.dumps(report))


if __name__ == "__main__":
    main(sys.argv[1])
