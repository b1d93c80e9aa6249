"""The simulation's clock: pacing, lockstep, pause and step (core/sim/_clock.py)."""

import threading
import time

import pytest

from bellow_ancf_ros.core.sim import SimulationClock


class Runner:
    """Steps ``clock`` in a thread as a simulator does; ``stop()`` joins it."""

    def __init__(self, clock):
        self.clock = clock
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while self.clock.wait_for_step():
            self.clock.advanced()

    def stop(self):
        self.clock.stop()
        self.thread.join(2.0)
        assert not self.thread.is_alive()


def steps_after(clock, wall_s):
    time.sleep(wall_s)
    return clock.steps


def reported_and_running(timeout_s=5.0, **reports):
    """A strict lockstep stepping in a :class:`Runner`: (clock, runner).

    10 ms steps, as fast as allowed; ``reports`` (who -> done until) given
    before its first step.
    """
    clock = SimulationClock(0.01, real_time_factor=0.0, lockstep_period_s=0.05,
                            lockstep_timeout_s=timeout_s)
    clock.pause()
    for who, t in reports.items():
        clock.done_until(t, who)
    r = Runner(clock)
    clock.unpause()
    return clock, r


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_real_time_factor_paces_the_steps(factor):
    clock = SimulationClock(0.01, real_time_factor=factor)
    t0 = time.monotonic()
    r = Runner(clock)
    assert clock.wait_until(40, 30.0)
    wall = time.monotonic() - t0
    r.stop()
    # 0.4 simulated seconds: 0.8 s at 0.5x, 0.2 s at 2x (never faster; slower on a busy machine)
    assert wall >= 0.4 / factor - 0.02
    assert wall < 0.4 / factor + 1.0


def test_factor_zero_runs_as_fast_as_it_can():
    clock = SimulationClock(0.01, real_time_factor=0.0)
    r = Runner(clock)
    assert clock.wait_until(2000, 10.0)   # 20 simulated seconds
    r.stop()
    assert clock.time_s == pytest.approx(clock.steps * 0.01, abs=0)


def test_pause_holds_step_takes_exactly_the_steps_asked_and_unpause_runs_again():
    clock = SimulationClock(0.01, real_time_factor=0.0)
    r = Runner(clock)
    clock.pause()
    time.sleep(0.05)
    held = clock.steps
    assert steps_after(clock, 0.3) == held
    with pytest.raises(ValueError, match="steps = 0 is not allowed"):
        clock.step(0)
    target = clock.step(7)
    assert target == held + 7 and clock.wait_until(target, 5.0)
    assert steps_after(clock, 0.2) == held + 7   # still paused
    clock.unpause()
    assert clock.wait_until(held + 100, 5.0)
    with pytest.raises(ValueError, match="running: pause it first"):
        clock.step(1)
    r.stop()


def test_lockstep_runs_at_most_one_period_ahead_of_the_newest_command():
    clock = SimulationClock(0.01, real_time_factor=0.0, lockstep_period_s=0.05,
                            lockstep_timeout_s=5.0)
    r = Runner(clock)
    assert clock.wait_until(300, 5.0)   # no command yet: free
    clock.pause()
    time.sleep(0.05)
    clock.command_arrived()
    at = clock.steps
    clock.unpause()
    # the next step would go beyond the newest command by more than the period: it waits
    assert steps_after(clock, 0.3) == at + 5
    assert clock.lockstep_waits == 1
    for k in range(2, 5):
        clock.command_arrived()
        assert steps_after(clock, 0.1) == at + 5 * k
    r.stop()
    assert clock.lockstep_timeouts == 0 and clock.lockstep_wait_s > 0.2


def test_a_controller_that_stops_answering_releases_the_lockstep_after_its_timeout():
    clock = SimulationClock(0.01, real_time_factor=0.0, lockstep_period_s=0.05,
                            lockstep_timeout_s=0.3)
    clock.command_arrived()
    t0 = time.monotonic()
    r = Runner(clock)
    assert clock.wait_until(5, 1.0)
    assert clock.wait_until(200, 5.0)   # free after the timeout
    assert time.monotonic() - t0 >= 0.3
    assert clock.lockstep_timeouts == 1
    clock.command_arrived()             # the controller is back: locked again
    at = clock.steps
    assert steps_after(clock, 0.2) == at + 5
    r.stop()


def test_bad_settings_named():
    with pytest.raises(ValueError, match="real_time_factor = -1 is not allowed: must be "
                                         "positive or 0"):
        SimulationClock(0.01, real_time_factor=-1)
    with pytest.raises(ValueError, match="lockstep_period_s = 0 is not allowed"):
        SimulationClock(0.01, lockstep_period_s=0)
    with pytest.raises(ValueError, match="step_s = 0 is not allowed"):
        SimulationClock(0)


def test_a_controller_that_reports_its_time_holds_the_simulation_to_it_step_by_step():
    clock, r = reported_and_running(**{'': 0.0})
    assert steps_after(clock, 0.2) == 1   # one step past the report, no further
    for k in range(1, 6):
        clock.done_until(clock.time_s)    # the controller caught up with the time reached
        assert steps_after(clock, 0.05) == k + 1
    clock.command_arrived()               # commands no longer move it on
    assert steps_after(clock, 0.1) == 6
    clock.done_until(0.02)                # an old report never moves it back
    assert steps_after(clock, 0.1) == 6
    r.stop()


def test_short_lockstep_waits_are_caught_up_so_the_factor_holds():
    """A controller that takes 25 ms for every 50 ms still gets the simulation at 1x.

    Re-anchoring the pacing after every wait ran the main job at 0.7x real time.
    """
    clock = SimulationClock(0.01, real_time_factor=1.0, lockstep_period_s=0.05,
                            lockstep_timeout_s=5.0)
    clock.done_until(0.05)
    stop = threading.Event()

    def controller():
        reported = 0.05
        while not stop.is_set():
            if clock.time_s >= reported - 1e-9:
                time.sleep(0.025)                   # its work on the newest period
                reported += 0.05
                clock.done_until(reported)
            time.sleep(0.001)
    worker = threading.Thread(target=controller, daemon=True)
    t0 = time.monotonic()
    r = Runner(clock)
    worker.start()
    assert clock.wait_until(100, 30.0)              # 1 simulated second
    wall = time.monotonic() - t0
    stop.set()
    r.stop()
    worker.join(2.0)
    assert clock.lockstep_waits >= 10 and clock.lockstep_timeouts == 0
    # 25 ms of work, 25 ms of steps caught up at 2x; paced from each wait's end instead:
    # 20 x (25 ms + 50 ms) = 1.5 s
    assert 0.98 <= wall < 1.25


def test_the_slowest_participant_holds_the_simulation_and_one_that_leaves_no_longer():
    clock, r = reported_and_running(controller=0.05, trajectory=0.02)
    assert steps_after(clock, 0.2) == 3          # 0.02 reached: the trajectory holds it
    assert clock.participants == ['controller', 'trajectory']
    clock.done_until(0.07, 'trajectory')
    assert steps_after(clock, 0.2) == 6          # now the controller (0.05) holds it
    clock.done_until(0.01, 'controller')         # an old report never moves it back
    clock.leave('controller')
    assert steps_after(clock, 0.2) == 8          # the trajectory alone: 0.07
    clock.leave('trajectory')                    # nobody left: free
    assert steps_after(clock, 0.2) > 20
    r.stop()


def test_a_participant_that_stops_reporting_is_forgotten_after_the_timeout():
    clock, r = reported_and_running(0.3, dead=0.02, alive=10.0)
    assert steps_after(clock, 0.15) == 3
    time.sleep(0.4)                              # the timeout: 'dead' is forgotten
    assert clock.lockstep_timeouts == 1 and clock.participants == ['alive']
    assert clock.wait_until(500, 5.0)            # held by 'alive' alone (10 s)
    assert clock.steps <= 1001
    r.stop()


def test_a_message_in_flight_holds_the_step_until_its_receiver_has_counted_it():
    clock, r = reported_and_running(publisher=1e6, controller=1e6)
    clock.received_here('/cmd', 0)                  # the simulation receives the commands
    clock.done_until(1e6, 'controller', received={'/target': 0})
    assert clock.wait_until(5, 5.0)
    clock.done_until(1e6, 'publisher', sent={'/target': 1})   # a target in flight
    held = steps_after(clock, 0.05)
    assert steps_after(clock, 0.2) == held           # no step while it is owed
    clock.done_until(1e6, 'controller', received={'/target': 1}, sent={'/cmd': 2})
    assert steps_after(clock, 0.2) == held           # now the commands it sent are owed here
    clock.received_here('/cmd')
    assert steps_after(clock, 0.2) == held
    clock.received_here('/cmd')                      # both arrived: it runs on
    assert clock.wait_until(held + 20, 5.0)
    assert clock.ledger() == ({'/target': 1, '/cmd': 2},
                              {'': {'/cmd': 2}, 'controller': {'/target': 1}})
    # a receiver with more than was counted as sent (a publisher outside the lockstep) holds
    # nothing; a sender that leaves is owed nothing
    clock.done_until(1e6, 'controller', received={'/target': 5})
    clock.done_until(1e6, 'publisher', sent={'/target': 7})
    held = steps_after(clock, 0.05)
    assert steps_after(clock, 0.2) == held
    clock.leave('publisher')
    assert clock.wait_until(held + 20, 5.0)
    assert clock.lockstep_timeouts == 0
    r.stop()


def test_a_message_lost_is_owed_no_more_after_the_timeout():
    clock, r = reported_and_running(0.3, publisher=1e6, controller=1e6)
    clock.done_until(1e6, 'controller', received={'/target': 0})
    clock.done_until(1e6, 'publisher', sent={'/target': 1})
    held = steps_after(clock, 0.1)
    time.sleep(0.4)
    assert clock.lockstep_timeouts == 1 and clock.wait_until(held + 20, 5.0)
    assert clock.participants == ['controller', 'publisher']   # both still in the lockstep
    r.stop()


def test_a_message_lost_is_forgiven_once_and_those_after_it_are_owed_again():
    clock, r = reported_and_running(0.3, publisher=1e6, controller=1e6)
    clock.done_until(1e6, 'controller', received={'/target': 0})
    clock.done_until(1e6, 'publisher', sent={'/target': 1})   # lost: never received
    time.sleep(0.5)
    assert clock.lockstep_timeouts == 1
    clock.done_until(1e6, 'publisher', sent={'/target': 2})   # the next one, in flight
    held = steps_after(clock, 0.05)
    assert steps_after(clock, 0.15) == held                   # owed (within the timeout)
    clock.done_until(1e6, 'controller', received={'/target': 1})   # it arrives: 1 of 2
    assert clock.wait_until(held + 20, 5.0) and clock.lockstep_timeouts == 1
    assert clock.ledger() == ({'/target': 2}, {'controller': {'/target': 2}})
    r.stop()


def test_messages_are_owed_to_a_receiver_from_its_first_report_on():
    clock, r = reported_and_running(controller=1e6)
    clock.sent_here('/measured_pressure', 3)         # before the forward node reported: not owed
    clock.done_until(1e6, 'forward', received={'/measured_pressure': 0})
    assert clock.wait_until(5, 5.0)
    clock.sent_here('/measured_pressure')            # in flight: no step until it is taken
    held = steps_after(clock, 0.05)
    assert steps_after(clock, 0.2) == held
    clock.done_until(1e6, 'forward', received={'/measured_pressure': 1})
    assert clock.wait_until(held + 20, 5.0)
    assert clock.lockstep_timeouts == 0
    assert clock.ledger() == ({'/measured_pressure': 4}, {'forward': {'/measured_pressure': 4}})
    clock.leave('forward')                            # gone: owed nothing
    clock.sent_here('/measured_pressure')
    held = clock.steps
    assert clock.wait_until(held + 20, 5.0)
    # a participant's messages likewise: a receiver that reports late owes none sent before
    clock.done_until(1e6, 'controller', sent={'/cmd': 7})
    clock.done_until(1e6, 'estimator', received={'/cmd': 0})
    held = clock.steps
    assert clock.wait_until(held + 20, 5.0)
    clock.done_until(1e6, 'controller', sent={'/cmd': 8})   # in flight: owed
    held = steps_after(clock, 0.05)
    assert steps_after(clock, 0.2) == held
    clock.done_until(1e6, 'estimator', received={'/cmd': 1})
    assert clock.wait_until(held + 20, 5.0) and clock.lockstep_timeouts == 0
    r.stop()
