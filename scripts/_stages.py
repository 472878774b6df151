"""The runner behind `make test` and `make check`: a graph of shell commands, each started as
soon as the stages it waits for have passed, logged to target/test-logs/<stage>.log, with a
table of where the time went at the end. A failed stage stops the others and prints the tail
of its log."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "target"
LOGS = TARGET / "test-logs"


def sh(*words: object) -> str:
    """One shell command line from words, each quoted."""
    return " ".join(shlex.quote(str(w)) for w in words)


@dataclass
class Stage:
    name: str
    command: str
    #: Stages that must pass first (those not in the run count as passed).
    after: tuple[str, ...] = ()
    env: dict[str, str] = field(default_factory=dict)
    what: str = ""
    #: pytest's JUnit report, when the stage runs pytest: the stage fails if a test was skipped
    #: (a missing tool, scene or driver would otherwise drop checks silently).
    junit: Optional[Path] = None
    #: How much lower than the others the stage runs (a nice value): for what is off the
    #: critical path, so that it takes only what the stages on it leave of the cores.
    nice: int = 0


def lowered(nice: int):
    """What a stage's process runs before its command (in its new session): its nice value
    raised by `nice`, and its session's autogroup's too. Linux schedules each session as one
    group (`/proc/sys/kernel/sched_autogroup_enabled`), and every stage is a session of its
    own, so a nice value alone ranks a stage's processes only among themselves: niced cargo
    builds took half of the two cores from the wheel's build beside them (the wheel took 413 s
    beside them, 215 s alone)."""

    def lower() -> None:
        os.nice(nice)
        try:
            with open("/proc/self/autogroup", "w") as f:
                f.write(str(nice))
        except OSError:
            pass  # no autogroups: the nice value alone ranks the stage

    return lower


def skipped(junit: Path) -> list[str]:
    """The tests a JUnit report says were skipped, with the reason."""
    if not junit.exists():
        return []
    return [
        f"{case.get('classname')}::{case.get('name')}: {s.get('message')}"
        for case in ET.parse(junit).iter("testcase")
        for s in case.iter("skipped")
    ]


def run(stages: list[Stage]) -> int:
    """Run `stages`, each once its `after` have passed; print progress and the timing table.
    Returns the exit status: 0 when every stage passed."""
    LOGS.mkdir(parents=True, exist_ok=True)
    names = {s.name for s in stages}
    pending = {s.name: s for s in stages}
    running: dict[str, tuple[subprocess.Popen, float, Stage]] = {}
    done: dict[str, tuple[float, float, str, float]] = {}
    t0 = time.monotonic()
    # Every stage is a session of its own, out of reach of the terminal's Ctrl-C: stopping
    # the runner (Ctrl-C, or SIGTERM from a CI timeout) stops every stage it started.
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        failed = _loop(names, pending, running, done, t0)
    except KeyboardInterrupt:
        print("\nstopped, and with it every stage it had started", flush=True)
        return 130
    finally:
        for p, _, _ in running.values():
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p, _, _ in running.values():
            p.wait()
    total = time.monotonic() - t0
    cpu = sum(d[3] for d in done.values())
    print(f"\n{'stage':<12} {'start s':>8} {'seconds':>8} {'CPU s':>8}  status")
    for name, (start, secs, status, used) in sorted(done.items(), key=lambda kv: kv[1][0]):
        print(f"{name:<12} {start:>8.0f} {secs:>8.0f} {used:>8.0f}  {status}")
    print(f"{'total':<12} {'':>8} {total:>8.0f} {cpu:>8.0f}  wall clock; CPU-seconds")
    if failed:
        tail = (LOGS / f"{failed}.log").read_text(errors="replace").splitlines()[-80:]
        print(f"\n{failed} failed; the end of target/test-logs/{failed}.log:\n" + "\n".join(tail))
        return 1
    return 0


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _reap(p: subprocess.Popen) -> Optional[float]:
    """The CPU-seconds (user and system) of a stage whose shell has exited, with every process
    it waited for; None while it runs. The stage's shell is reaped here, with its rusage, and
    its exit status given to `p`."""
    pid, status, usage = os.wait4(p.pid, os.WNOHANG)
    if pid == 0:
        return None
    p.returncode = os.waitstatus_to_exitcode(status)
    return usage.ru_utime + usage.ru_stime


def _loop(
    names: set[str],
    pending: dict[str, Stage],
    running: dict[str, tuple[subprocess.Popen, float, Stage]],
    done: dict[str, tuple[float, float, str, float]],
    t0: float,
) -> Optional[str]:
    """Start each stage once its `after` have passed, until all are done or one fails (the
    others are then stopped); the failed stage's name, or None."""
    failed = None
    while pending or running:
        for name, s in list(pending.items()):
            if all(a in done or a not in names for a in s.after):
                with open(LOGS / f"{name}.log", "w") as log:
                    p = subprocess.Popen(
                        s.command,
                        shell=True,
                        cwd=ROOT,
                        env=dict(os.environ, **s.env),
                        stdout=log,
                        stderr=subprocess.STDOUT,
                        start_new_session=True,
                        preexec_fn=lowered(s.nice) if s.nice else None,
                    )
                running[name] = (p, time.monotonic(), s)
                del pending[name]
                print(f"[{time.monotonic() - t0:5.0f} s] {name}: {s.what}", flush=True)
        time.sleep(0.2)
        for name, (p, start, s) in list(running.items()):
            used = _reap(p)
            if used is None:
                continue
            rc = p.returncode
            del running[name]
            if rc == 0 and s.junit is not None and skipped(s.junit):
                rc = 1
                with open(LOGS / f"{name}.log", "a") as log:
                    log.write("\nno test may be skipped here:\n" + "\n".join(skipped(s.junit)))
            now = time.monotonic()
            done[name] = (start - t0, now - start, "ok" if rc == 0 else f"FAILED ({rc})", used)
            print(f"[{now - t0:5.0f} s] {name}: {done[name][2]} in {now - start:.0f} s", flush=True)
            if rc != 0 and failed is None:
                failed = name
        if failed:
            for p, _, _ in running.values():
                os.killpg(p.pid, signal.SIGTERM)
            for name, (p, start, _) in running.items():
                p.wait()
                done[name] = (start - t0, time.monotonic() - start, "stopped", 0.0)
            running.clear()
            pending.clear()
    return failed
