"""The simulation's clock: fixed steps, paced against the wall clock, lockstep, pause and step.

A simulator that is the clock (Gazebo, Chrono::ROS) advances its physics by
a fixed step and publishes the time it reached; every node on simulation
time then runs its timers and windows on it, so a slow computer slows the
simulation instead of changing its result.  :class:`SimulationClock` decides
*when* the next step may be taken; the caller takes it and calls
:meth:`SimulationClock.advanced`:

* ``real_time_factor``: simulated seconds per wall second (1: real time;
  0: as fast as the steps can be taken).  A step that is late by more than
  :data:`MAX_LATE_S` re-anchors the pacing (no long catch-up burst); a
  shorter delay, such as a lockstep wait for the controller, is caught up
  at up to :data:`CATCH_UP` times the factor, so that a controller that
  keeps up on average keeps the factor.
* ``lockstep_period_s`` (lockstep on when set): the simulation runs at most
  this far ahead of the newest command (:meth:`command_arrived`), so a
  controller that stops commanding holds the simulation back.  A command
  does not say which time it answers, so a controller that lags behind at
  its usual cadence is not seen: a controller that reports the time up to
  which it has done its work (:meth:`done_until`, the inverse node's
  ``lockstep_clock``) makes the lockstep strict: no step beyond that time.
  Several participants may report, each under its own name (a controller,
  a trajectory publisher that reports its next tick's time): the simulation
  waits for the slowest, and one that :meth:`leave` s holds it no longer.
  Until the first command or report, it runs free; after a wait of
  ``lockstep_timeout_s`` wall seconds (counted in :attr:`lockstep_timeouts`)
  the participants that held it back are forgotten until they report again
  (a participant stopped or dead), and it runs free if none is left.
* Messages owed: a report may also count the messages its participant has
  sent and received on named topics (``sent``, ``received``; cumulative),
  and the simulation counts what it receives and sends itself
  (:meth:`received_here`, :meth:`sent_here`: its sensors' readings).  A
  receiver owes what was sent from its first report of a topic on.  No
  step is taken while a receiver has counted fewer messages on a topic
  than the participants have sent on it: a
  message in flight (a target, a command) is seen at the same simulated
  time however long the computer takes to deliver it.  Only reliable
  topics should be counted (a lost best-effort message would be owed until
  the timeout); a wait for a message ends, as any lockstep wait, after
  ``lockstep_timeout_s``, and what was sent until then counts as received.
* :meth:`pause`, :meth:`unpause`, :meth:`step`: no step while paused except
  the ones asked for, which are taken at once (neither paced nor locked).

Thread-safe: one thread waits in :meth:`wait_for_step` and steps; others
pause, step, stop and report commands.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

__all__ = ['CATCH_UP', 'MAX_LATE_S', 'SimulationClock']

#: A step later than this against the pacing [wall s] re-anchors it (no catch-up burst).
MAX_LATE_S = 0.1
#: A delay is caught up at most this many times the real-time factor (a burst at the computer's
#: speed outran the nodes that are not in the lockstep: the recorder lost 16 % of the poses).
CATCH_UP = 2.0
#: Longest single wait [wall s] before the conditions are looked at again.
_POLL_S = 0.1


class SimulationClock:
    """When the next fixed step of a simulation may be taken (see the module's text)."""

    def __init__(self, step_s: float, real_time_factor: float = 1.0,
                 lockstep_period_s: float | None = None, lockstep_timeout_s: float = 1.0,
                 wall: Callable[[], float] = time.monotonic) -> None:
        """``step_s`` [s]; ``real_time_factor`` >= 0; ``lockstep_period_s`` > 0 or None."""
        for name, value, ok in (('step_s', step_s, step_s > 0),
                                ('real_time_factor', real_time_factor, real_time_factor >= 0),
                                ('lockstep_timeout_s', lockstep_timeout_s,
                                 lockstep_timeout_s > 0),
                                ('lockstep_period_s', lockstep_period_s,
                                 lockstep_period_s is None or lockstep_period_s > 0)):
            if not ok:
                raise ValueError(f'{name} = {value} is not allowed: must be positive'
                                 + (' or 0' if name == 'real_time_factor' else ''))
        self.step_s = float(step_s)
        self.real_time_factor = float(real_time_factor)
        self.lockstep_period_s = lockstep_period_s
        self.lockstep_timeout_s = float(lockstep_timeout_s)
        self._wall = wall
        self._cond = threading.Condition()
        self._stopped = False
        self.steps = 0                 # steps taken since the start
        self.paused = False
        self._pending = 0              # steps asked for while paused
        self._anchor: tuple[float, float] | None = None   # (wall, simulated) of the pacing
        self._last_wall = -float('inf')   # wall time of the newest step
        self._command_t: float | None = None   # simulated time of the newest command
        self._done: dict[str, float] = {}      # participant -> its work done until [s]
        self._sent: dict[str, dict[str, int]] = {}       # participant -> topic -> messages
        self._received: dict[str, dict[str, int]] = {}   # receiver ('' : here) -> topic -> n
        self._forgiven: dict[str, dict[str, int]] = {}   # receiver -> topic -> lost messages
        self._free = True              # lockstep released (no command yet, or timed out)
        self._wait_since: float | None = None  # wall time a lockstep wait began
        self.lockstep_waits = 0        # steps that waited for a command
        self.lockstep_timeouts = 0     # waits given up after lockstep_timeout_s
        self.lockstep_wait_s = 0.0     # wall time spent waiting for commands
        #: the newest timeout: (simulated time, participants behind, receivers owing messages)
        self.last_timeout: tuple[float, list, list] | None = None

    # ------------------------------------------------------------ reading
    @property
    def time_s(self) -> float:
        """Simulated time reached [s] (steps times the step: no accumulated rounding)."""
        return self.steps * self.step_s

    def measured_factor(self, since: tuple[float, float]) -> tuple[float, tuple[float, float]]:
        """Simulated seconds per wall second since ``since`` = (wall, simulated), and now's pair.

        The achieved real-time factor over a report period (NaN if no wall
        time passed).
        """
        now = (self._wall(), self.time_s)
        dw = now[0] - since[0]
        return ((now[1] - since[1]) / dw if dw > 0 else float('nan')), now

    # ------------------------------------------------------------ control
    def pause(self) -> None:
        """No further step (except those asked for by :meth:`step`)."""
        with self._cond:
            self.paused = True
            self._cond.notify_all()

    def unpause(self) -> None:
        """Run again, paced from now."""
        with self._cond:
            self.paused, self._anchor = False, None
            self._cond.notify_all()

    def step(self, n: int) -> int:
        """While paused: take ``n`` more steps at once; returns the step count to wait for.

        ValueError when running (pause first) or for ``n`` < 1.
        """
        if int(n) < 1:
            raise ValueError(f'steps = {n} is not allowed: at least 1')
        with self._cond:
            if not self.paused:
                raise ValueError('the simulation is running: pause it first')
            self._pending += int(n)
            self._cond.notify_all()
            return self.steps + self._pending

    def wait_until(self, steps: int, timeout_s: float) -> bool:
        """Wait (wall ``timeout_s`` at most) until ``steps`` steps are taken; True if they are."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while self.steps < steps and not self._stopped:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return self.steps >= steps

    def command_arrived(self) -> None:
        """A command came: the lockstep's reference moves to the simulated time now."""
        with self._cond:
            self._command_t, self._free = self.time_s, False
            self._cond.notify_all()

    def done_until(self, t: float, who: str = '', sent: dict | None = None,
                   received: dict | None = None) -> None:
        """Participant ``who`` has done its work up to simulated time ``t``: the strict lockstep.

        From the first report on, no step goes beyond the oldest of the
        participants' newest reports (their computation takes no simulated
        time); an older report than one already given changes nothing.
        ``sent`` / ``received``: the messages ``who`` has sent / received so
        far per topic (cumulative counts; see the module's text).  A
        receiver owes the messages sent from its first report of a topic on:
        those sent before it (a node started late, its subscription not yet
        matched) never reach it.
        """
        with self._cond:
            self._done[who] = max(self._done.get(who, float(t)), float(t))
            known = self._received.get(who, {})
            new = [t for t in (received or {}) if t not in known]
            if new:   # a new receiver of a topic: what was sent before it is not owed
                sent_before = self._sent_totals()
                for topic in new:
                    before, n = sent_before.get(topic, 0), int(received[topic])
                    if before > n:
                        self._forgiven.setdefault(who, {})[topic] = before - n
            for book, counts in ((self._sent, sent), (self._received, received)):
                if counts:
                    mine = book.setdefault(who, {})
                    for topic, n in counts.items():
                        mine[topic] = max(mine.get(topic, 0), int(n))
            self._free = False
            self._cond.notify_all()

    def sent_here(self, topic: str, n: int = 1) -> None:
        """The simulation itself sent ``n`` more messages on ``topic`` (e.g. its sensors').

        Owed to every receiver that counts ``topic`` in its reports, as any
        participant's (:meth:`done_until`).
        """
        with self._cond:
            mine = self._sent.setdefault('', {})
            mine[topic] = mine.get(topic, 0) + int(n)
            self._cond.notify_all()

    def received_here(self, topic: str, n: int = 1) -> None:
        """The simulation itself received ``n`` more messages on ``topic`` (e.g. commands)."""
        with self._cond:
            mine = self._received.setdefault('', {})
            mine[topic] = mine.get(topic, 0) + int(n)
            self._cond.notify_all()

    def ledger(self) -> tuple[dict[str, int], dict[str, dict[str, int]]]:
        """The messages counted so far: (sent per topic, received per receiver and topic).

        The simulation's own receiver is named ``''``.
        """
        with self._cond:
            return self._sent_totals(), {who: self._counted(who) for who in self._received}

    def _counted(self, who: str) -> dict[str, int]:
        """What ``who`` received per topic, the messages forgiven included (lock held)."""
        lost = self._forgiven.get(who, {})
        return {topic: n + lost.get(topic, 0) for topic, n in self._received[who].items()}

    def _sent_totals(self) -> dict[str, int]:
        sent: dict[str, int] = {}
        for counts in self._sent.values():
            for topic, n in counts.items():
                sent[topic] = sent.get(topic, 0) + n
        return sent

    def _forgive(self) -> None:
        """Count every message sent so far as received (lock held): a lost one is owed no more.

        Kept apart from the receiver's own counts, which go on counting what
        it really received (one lost message must not be owed again after
        every message that follows it).
        """
        sent = self._sent_totals()
        for who in self._received:
            lost = self._forgiven.setdefault(who, {})
            for topic, n in self._counted(who).items():
                lost[topic] = lost.get(topic, 0) + max(sent.get(topic, 0) - n, 0)

    def _owed(self) -> list[str]:
        """The receivers that have not yet received every message sent to them (lock held)."""
        sent, owed = self._sent_totals(), []
        for who in self._received:
            counts = self._counted(who)
            if any(counts[topic] < n for topic, n in sent.items() if topic in counts):
                owed.append(who)
        return owed

    def leave(self, who: str = '') -> None:
        """Participant ``who`` no longer holds the simulation back (it stopped)."""
        with self._cond:
            self._done.pop(who, None)
            self._sent.pop(who, None)
            self._received.pop(who, None)
            self._forgiven.pop(who, None)
            self._cond.notify_all()

    @property
    def done_s(self) -> float | None:
        """The time the strict lockstep holds the simulation to (None: no report)."""
        with self._cond:
            return min(self._done.values()) if self._done else None

    @property
    def participants(self) -> list[str]:
        """The names of the participants the strict lockstep waits for."""
        with self._cond:
            return sorted(self._done)

    def stop(self) -> None:
        """End :meth:`wait_for_step` (it returns False)."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()

    # ------------------------------------------------------------ stepping
    def _locked(self) -> bool:
        """True while lockstep holds the next step back (called with the lock held)."""
        if self.lockstep_period_s is None or self._free:
            return False
        if self._done:   # strict: every participant has done its work until the time reached
            return self.time_s > min(self._done.values()) + 1e-9 or bool(self._owed())
        if self._command_t is None:
            return False
        return self.time_s + self.step_s - self._command_t > self.lockstep_period_s + 1e-12

    def wait_for_step(self) -> bool:
        """Block until the next step may be taken; False once stopped."""
        with self._cond:
            while not self._stopped:
                if self._pending > 0:
                    return True
                if self.paused:
                    self._cond.wait(_POLL_S)
                    continue
                now = self._wall()
                if self._locked():
                    if self._wait_since is None:
                        self._wait_since = now
                        self.lockstep_waits += 1
                    left = self._wait_since + self.lockstep_timeout_s - now
                    if left <= 0:   # stopped answering: forget who holds it back, until it does
                        self.lockstep_timeouts += 1
                        behind = [w for w, t in self._done.items() if self.time_s > t + 1e-9]
                        self.last_timeout = (self.time_s, behind, self._owed())
                        for who in behind:
                            del self._done[who]
                        self._forgive()   # a message lost: owed no longer
                        self._free = not self._done
                    else:
                        self._cond.wait(min(left, _POLL_S))
                    continue
                if self._wait_since is not None:   # a wait ended: catch up (MAX_LATE_S at most)
                    self.lockstep_wait_s += now - self._wait_since
                    self._wait_since = None
                if self.real_time_factor > 0:
                    if self._anchor is None:
                        self._anchor = (now, self.time_s)
                    due = max(self._anchor[0] + (self.time_s + self.step_s - self._anchor[1])
                              / self.real_time_factor,
                              self._last_wall + self.step_s / (CATCH_UP * self.real_time_factor))
                    if due - now > 0:
                        self._cond.wait(min(due - now, _POLL_S))
                        continue
                    if now - due > MAX_LATE_S:
                        self._anchor = (now, self.time_s)
                return True
            return False

    def advanced(self) -> None:
        """The caller took the step: the simulated time moves on by one step."""
        with self._cond:
            self.steps += 1
            self._last_wall = self._wall()
            if self._pending > 0:
                self._pending -= 1
            self._cond.notify_all()
