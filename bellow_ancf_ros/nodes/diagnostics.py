"""Diagnostics of the nodes on ``/diagnostics``: statuses, the heartbeat, refusals, throttling.

Like diagnostic_updater: a 1 Hz status heartbeat per node
(:class:`Heartbeat`), per-event statuses (:func:`publish_diagnostic`), rate
limits for floods of refused input (:class:`Refusals`) and for per-solve
statuses at high solve rates (:class:`ThrottledStatus`).
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from . import worker
from .ros_util import WARN_THROTTLE_S, control_clock

__all__ = [
    'HEARTBEAT_PERIOD_S', 'REFUSAL_DIAG_INTERVAL_S', 'STATUS_PERIOD_S', 'Heartbeat', 'Refusals',
    'ThrottledStatus', 'diagnostic_status', 'inverse_values', 'publish_diagnostic',
    'lifecycle_level', 'lifecycle_state', 'matched_subscribers', 'solve_outcome',
    'solve_values',
]

#: Minimum interval between two WARN diagnostics of the same refusal reason [s].
REFUSAL_DIAG_INTERVAL_S = 0.1
#: Period of the status heartbeat on ``/diagnostics`` [s] (diagnostic_updater's default).
HEARTBEAT_PERIOD_S = 1.0
#: Per-solve statuses: an unchanged one is published at most this often [s] (10 Hz).
STATUS_PERIOD_S = 0.1


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: dict) -> DiagnosticStatus:
    """Build a DiagnosticStatus with the key/values of ``values`` (as strings)."""
    st = DiagnosticStatus()
    st.name = name
    st.hardware_id = hardware_id
    st.level = level
    st.message = message
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    return st


def publish_diagnostic(node, pub, name: str, hardware_id: str, level: bytes, message: str,
                       values: dict) -> None:
    """Publish one DiagnosticStatus on ``pub`` (no-op without a publisher or once destroyed)."""
    if pub is None:
        return
    arr = DiagnosticArray()
    arr.header.stamp = node.get_clock().now().to_msg()
    arr.status = [diagnostic_status(name, hardware_id, level, message, values)]
    try:
        pub.publish(arr)
    except Exception:  # noqa: BLE001 - publisher destroyed meanwhile
        pass


class Heartbeat:
    """Periodic node status on ``/diagnostics`` (1 Hz), like diagnostic_updater.

    Every period one DiagnosticStatus named ``'<node>: status'`` is published
    with the level, message and key/values of ``status()`` (a callable
    returning ``(level, message, values)``) merged with those of every
    source added by :meth:`add_source`.  A source is a callable returning
    either a dict of key/values, or ``(level, message, values)``: its level
    raises the status level (OK < WARN < ERROR), its message is appended.
    This is how a node part adds its own fields (e.g. a feedback state)
    without touching the node's base status.
    """

    def __init__(self, node, pub, status: Callable[[], tuple],
                 hardware_id: Callable[[], str], period_s: float = HEARTBEAT_PERIOD_S) -> None:
        self.node, self.pub = node, pub
        self._status, self._hardware_id = status, hardware_id
        self._sources: list = []
        self.published = 0
        self.name = f'{node.get_name()}: status'
        self._timer = node.create_timer(period_s, self.publish)

    def add_source(self, source: Callable[[], Any]) -> None:
        """Add a callable contributing key/values (and optionally a level) to every beat."""
        self._sources.append(source)

    def compose(self) -> tuple:
        """The current ``(level, message, values)`` with every source merged in."""
        level, message, values = self._status()
        values = dict(values)
        for source in self._sources:
            try:
                extra = source()
            except Exception as exc:  # noqa: BLE001 - one bad source must not stop the beat
                level = max(level, DiagnosticStatus.WARN)
                values[f'source_error_{len(values)}'] = f'{type(exc).__name__}: {exc}'
                continue
            if isinstance(extra, tuple):
                lvl, msg, extra = extra
                level = max(level, lvl)
                if msg:
                    message = f'{message}; {msg}' if message else msg
            values.update(extra or {})
        return level, message, values

    def publish(self) -> None:
        """Publish one status now (the timer calls this every period)."""
        level, message, values = self.compose()
        publish_diagnostic(self.node, self.pub, self.name, self._hardware_id(), level, message,
                           values)
        self.published += 1


def matched_subscribers(pub) -> int:
    """How many subscriptions ``pub`` has matched (0 without it, or once destroyed).

    For ``pressure_command``: the regulators' driver and any recorder.  A
    driver that is not matched yet misses the commands sent meanwhile and
    then takes the newest at once (a step).
    """
    try:
        return 0 if pub is None else int(pub.get_subscription_count())
    except Exception:  # noqa: BLE001 - destroyed meanwhile (a cleanup)
        return 0


def solve_values(stats: worker.SolveStats) -> dict:
    """Heartbeat key/values of a :class:`worker.SolveStats` (times in ms, age in s)."""
    s = stats.summary()

    def ms(v):
        return 'n/a' if v is None or not math.isfinite(v) else f'{v * 1e3:.3f}'
    age = s['last_solve_age_s']
    return {
        'solves': s['count'],
        'last_solve_age_s': 'never' if age is None else f'{age:.3f}',
        'last_solve_ok': 'n/a' if s['last_ok'] is None else str(s['last_ok']).lower(),
        'solve_ms_last': ms(s['last_s']),
        'solve_ms_median': ms(s['median_s']),
        'solve_ms_p95': ms(s['p95_s']),
        'solve_ms_max': ms(s['max_s']),
        'solve_stats_window': s['window'],
    }


def inverse_values(inv, dt: float, payload: float, unit: str) -> dict:
    """Key/values of one inverse solve (an ``InverseResult``, ``dt`` seconds) for its status."""
    fw = inv.forward
    return {
        'solve_time_ms': f'{dt * 1e3:.3f}',
        'iterations': inv.iterations,
        'residual_norm': 'nan' if fw is None else f'{fw.residual_norm:.3e}',
        'position_error_m': f'{inv.position_error_m:.3e}',
        'angle_error_rad': ('n/a' if inv.angle_error_rad is None
                            else f'{inv.angle_error_rad:.3e}'),
        'reachable': str(bool(inv.reachable)).lower(),
        'active_limits': ' '.join(str(int(v)) for v in inv.active_limits),
        'status': inv.status,
        'payload_kg': payload,
        'pressure_unit': unit,
    }


def lifecycle_state(node, active: bool, configured: bool) -> str:
    """Label of a lifecycle node's current state (``unconfigured``, ``inactive``, ``active``...).

    What rclpy's state machine says; without one, or when it cannot say,
    the node's own flags: ``active``, else ``configured`` (inactive), else
    unconfigured.
    """
    sm = getattr(node, '_state_machine', None)
    if sm is not None:
        try:
            return str(sm.current_state[1])
        except Exception:  # noqa: BLE001 - fall back on the node's own flags
            pass
    return 'active' if active else 'inactive' if configured else 'unconfigured'


def lifecycle_level(state: str, yielded_to: str = '', last_solve_ok=None,
                    configure_error: str = '', recovery: str = '',
                    subscribers: int | None = None) -> tuple:
    """A controller's heartbeat level and message for its lifecycle ``state``.

    ``yielded_to``: why it went inactive for another publisher of its
    commands ('' when it did not); ``last_solve_ok``: False when the last
    solve failed; ``configure_error``: why the last configure failed, and
    ``recovery`` the way out; ``subscribers``: how many subscriptions its
    commands have matched (0 while active: nothing hears them, a WARN).
    """
    if state == 'inactive' and yielded_to:
        return DiagnosticStatus.ERROR, f'inactive: {yielded_to}'
    if state == 'active':
        if last_solve_ok is False:
            return DiagnosticStatus.WARN, 'active; the last solve failed'
        if subscribers == 0:
            return (DiagnosticStatus.WARN, 'active, but nothing subscribes to its pressure '
                    'commands: no regulator driver hears them (check the topic and remappings)')
        return DiagnosticStatus.OK, 'active: pressure commands enabled'
    if state == 'inactive':
        return DiagnosticStatus.OK, 'inactive: pressure commands disabled'
    if configure_error:
        return (DiagnosticStatus.ERROR,
                f'unconfigured: configure failed ({configure_error}); {recovery}'.rstrip('; '))
    return DiagnosticStatus.WARN, f'{state}: no pressure commands'


def solve_outcome(inv, usable: bool, budget: bool, more: bool, unsafe=None,
                  feedback_state: str | None = None) -> tuple:
    """What one inverse solve means: ``(level, message, counter or None, logged)``.

    ``usable``: the solve gave an equilibrium; ``budget``: it ended on its
    time or iteration budget (``more``: its next slice is queued);
    ``unsafe``: why the safety gate refused its pressures, or None;
    ``feedback_state``: the closed loop's state when it ran without fresh
    measured poses, or None.  ``counter``: the node's counter to count it
    in; ``logged``: the message also goes to the log (WARN or ERROR, as
    ``level``).
    """
    ok, warn, error = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
    going = ', continuing' if more else ''
    if not usable and budget:
        return (warn if more else error, f'no usable answer within the solve budget, last '
                f'command kept{going}: {inv.message}', None if more else 'failed', True)
    if not usable:
        return error, f'solve failed ({inv.message}); last command kept', 'failed', True
    if unsafe is not None:
        return (error, f'solver output refused by the safety gate ({unsafe}); last command '
                'kept', 'failed', True)
    if budget:
        return (warn, f'solve budget used up, best in-limit pressures so far sent{going}: '
                f'{inv.message}', 'over_budget', True)
    if inv.reachable and feedback_state is not None:
        return (warn, f'target reached without fresh measured poses: feedback '
                f'{feedback_state}', None, False)
    if inv.reachable:
        return ok, 'target reached', None, False
    return (warn, f'target unreachable, best reachable pressures sent: {inv.message}',
            'unreachable', True)


#: Kinds of refusal whose log lines :class:`Refusals` throttles apart (the oldest forgotten).
_REFUSAL_KINDS = 64
#: The numbers in a refusal's reason (values, stamps): its kind is the reason without them.
_NUMBERS = re.compile(r'[-+]?(?:\d+\.?\d*(?:e[-+]?\d+)?|nan|inf)', re.IGNORECASE)


class Refusals:
    """Reporting of refused inputs: a warning per kind of reason, a WARN diagnostic rate-limited.

    The log line is throttled per kind of reason (the reason without its
    numbers), at most one every :data:`WARN_THROTTLE_S`: a NaN target right
    after a target in a wrong frame is logged too (rclpy's throttle, per
    call site, let the first hide the second).  At most one WARN diagnostic
    every :data:`REFUSAL_DIAG_INTERVAL_S` per reason (a flood of bad input
    cannot flood ``/diagnostics``).  ``what`` names the input (``targets``,
    ``pressures``).
    """

    def __init__(self, node, what: str, publish_diag) -> None:
        self.node, self.what, self.publish_diag = node, what, publish_diag
        self._clock = control_clock(node)   # the rate limit: control time (use_sim_time)
        self._last = ('', -math.inf)
        self._logged: dict[str, float] = {}   # kind of reason -> when last logged (monotonic)

    def report(self, reason: str, total: int) -> None:
        """Log and report one refusal (``total``: refusals so far)."""
        kind = _NUMBERS.sub('#', reason)
        t = time.monotonic()
        if t - self._logged.get(kind, -math.inf) >= WARN_THROTTLE_S:
            self._logged.pop(kind, None)
            if len(self._logged) >= _REFUSAL_KINDS:
                del self._logged[next(iter(self._logged))]
            self._logged[kind] = t
            self.node.get_logger().warning(f'{self.what} refused: {reason}')
        now = self._clock.now()
        if reason != self._last[0] or now - self._last[1] >= REFUSAL_DIAG_INTERVAL_S:
            self._last = (reason, now)
            self.publish_diag(DiagnosticStatus.WARN, f'{self.what} refused: {reason}',
                              {f'refused_{self.what}': total})


class ThrottledStatus:
    """Per-event statuses at a bounded rate: a new level or message at once, repeats at 10 Hz.

    At a high solve rate a status per solve costs the solver thread about
    0.3 ms (message building and publishing) for news that rarely changes.
    :meth:`submit` publishes at once when the level or the message differs
    from the last status published, or when ``period_s`` has passed since
    then; otherwise the status is kept and the node's timer publishes the
    newest one kept at the end of the period (:meth:`flush`), so the latest
    values always arrive within ``period_s``.
    """

    def __init__(self, node, pub, name: str, period_s: float = STATUS_PERIOD_S) -> None:
        self.node, self.pub, self.name, self.period_s = node, pub, name, period_s
        self._clock = control_clock(node)   # the throttle: control time, as the flush timer
        self._lock = threading.Lock()
        self._last = (None, None, -math.inf)  # level, message, time of the last published
        self._pending = None
        self.published = self.deferred = 0
        self._timer = node.create_timer(period_s, self.flush)

    def submit(self, hardware_id: str, level: bytes, message: str, values: dict) -> None:
        """Publish this status now, or keep it for :meth:`flush` (see the class docstring)."""
        now = self._clock.now()
        with self._lock:
            lvl, msg, t = self._last
            if (level, message) == (lvl, msg) and now - t < self.period_s:
                self._pending = (hardware_id, level, message, values)
                self.deferred += 1
                return
            self._pending = None
            self._publish(now, hardware_id, level, message, values)

    def flush(self) -> None:
        """Publish the status kept by :meth:`submit`, if any (the node's timer calls it)."""
        with self._lock:
            if self._pending is not None:
                pending, self._pending = self._pending, None
                self._publish(self._clock.now(), *pending)

    def _publish(self, now, hardware_id, level, message, values) -> None:
        self._last = (level, message, now)
        self.published += 1
        publish_diagnostic(self.node, self.pub, self.name, hardware_id, level, message, values)
