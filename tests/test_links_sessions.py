"""The first contact of a session (`planecal.links.sessions.plan_contact`), for each
stated behaviour, the operator's flags and an unstated cell; the statement in robot.json."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.base.paths import data_path
from planecal.links.sessions import (SILENCE_MARGIN_S, LastSession, SessionBehaviour,
                                     plan_contact, stated_behaviour)

NOW = 1_764_000_000.0
L = np.array([16094, 11574, 10714, 41376, 12880, -16979])  # the last delta
R = np.full(6, 8388608)
KEEP = SessionBehaviour("keep")
SILENCE = SessionBehaviour("fresh_after_silence", 2.0)
CLIENT = SessionBehaviour("fresh_each_client")


def last(delta=L, sent_at=NOW - 10.0, client="10.0.0.2:5556") -> LastSession:
    return LastSession(Path("fd11-10.0.0.1-5555.state"), np.asarray(delta), R.copy(), sent_at,
                       client)


def test_a_kept_reference_repeats_the_last_delta_and_checks_the_reference():
    c = plan_contact(KEEP, last(), None, "10.0.0.2:5556", NOW)
    assert c.kind == "kept" and c.wait_s == 0
    np.testing.assert_array_equal(c.held, L)
    np.testing.assert_array_equal(c.reference, R)


@pytest.mark.parametrize("silent_s, wait_s", [
    (10.0, 0.0),                       # the resume 10 s later: fresh already
    (2.0 + SILENCE_MARGIN_S, 0.0),     # exactly the silence and its margin
    (1.0, 1.5),                        # a quick restart: wait the rest
    (0.0, 2.5),
    (-3600.0, 2.5),                    # the clock went back: the whole silence
])
def test_a_fresh_reference_after_silence_is_waited_for(silent_s, wait_s):
    c = plan_contact(SILENCE, last(sent_at=NOW - silent_s), None, "10.0.0.2:5556", NOW)
    assert c.kind == "fresh" and c.reference is None and not c.held.any()
    assert c.wait_s == pytest.approx(wait_s, abs=1e-3)


def test_an_unknown_time_waits_the_whole_silence():
    c = plan_contact(SILENCE, last(sent_at=None), None, "10.0.0.2:5556", NOW)
    assert c.kind == "fresh" and c.wait_s == pytest.approx(2.5)


def test_a_new_client_address_is_fresh_and_the_same_one_keeps():
    same = plan_contact(CLIENT, last(), None, "10.0.0.2:5556", NOW)
    other = plan_contact(CLIENT, last(), None, "10.0.0.2:40001", NOW)
    assert same.kind == "kept" and np.array_equal(same.held, L)
    assert other.kind == "fresh" and not other.held.any() and other.wait_s == 0
    with pytest.raises(InputError, match="records no client address.*--rt-fresh.*--rt-keep"):
        plan_contact(CLIENT, last(client=None), None, "10.0.0.2:5556", NOW)


def test_an_unstated_behaviour_asks_in_one_line_unless_both_agree():
    with pytest.raises(InputError) as e:
        plan_contact(None, last(), None, "10.0.0.2:5556", NOW, where="models/mc70/robot.json")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("models/mc70/robot.json: controller.sessions is "
                                              "not stated")
    assert "--rt-fresh" in msg and "--rt-keep" in msg and str(L.tolist()) in msg
    # left at delta 0: both behaviours want a first packet of 0
    assert plan_contact(None, last(delta=np.zeros(6, int)), None, "x:1", NOW).kind == "either"
    # never driven by planecal: nothing to repeat
    assert plan_contact(None, None, None, "x:1", NOW).kind == "either"


@pytest.mark.parametrize("behaviour", [None, KEEP, SILENCE, CLIENT])
def test_the_operators_statement_wins(behaviour):
    fresh = plan_contact(behaviour, last(sent_at=NOW), "fresh", "x:1", NOW)
    keep = plan_contact(behaviour, last(sent_at=NOW), "keep", "x:1", NOW)
    # a controller that takes a fresh reference only after its silence: still waited for
    wait = 2.0 + SILENCE_MARGIN_S if behaviour is SILENCE else 0
    assert fresh.kind == "fresh" and fresh.wait_s == wait and "--rt-fresh" in fresh.why
    assert keep.kind == "kept" and np.array_equal(keep.held, L) and "--rt-keep" in keep.why


def test_the_statement_is_read_from_robot_json(tmp_path):
    assert stated_behaviour(data_path("models", "mc70", "robot.json")) is None  # unknown
    doc = json.loads(data_path("models", "mc70", "robot.json").read_text())
    doc["controller"]["sessions"] = {"reference": "fresh_after_silence", "silence_s": 2.0,
                                     "source": "measured"}
    p = tmp_path / "robot.json"
    p.write_text(json.dumps(doc))
    b = stated_behaviour(p)
    assert (b.reference, b.silence_s) == ("fresh_after_silence", 2.0)
    assert b.describe() == "takes a new reference after 2 s of silence"
    doc["controller"]["sessions"] = {"reference": "fresh_after_silence"}
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"robot.json: controller.sessions.silence_s: "
                                         r"fresh_after_silence needs silence_s"):
        stated_behaviour(p)
    doc["controller"]["sessions"] = {"reference": "boot"}
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"controller.sessions.reference: 'boot' is not a "
                                         r"reference behaviour \(keep, fresh_after_silence, "
                                         r"fresh_each_client\)"):
        stated_behaviour(p)


def test_a_behaviour_is_checked_when_made():
    with pytest.raises(ValueError):
        SessionBehaviour("session")
    with pytest.raises(ValueError):
        SessionBehaviour("keep", 2.0)
    with pytest.raises(ValueError):
        SessionBehaviour("fresh_after_silence")


@pytest.mark.parametrize("silent_s, wait_s", [(0.3, 2.2), (10.0, 0.0), (None, 2.5)])
def test_rt_fresh_on_a_cell_fresh_after_silence_waits_the_rest(silent_s, wait_s):
    """--rt-fresh right after a stop, on a cell whose controller takes a fresh reference
    only after 2 s of silence: the first packet of 0 waits the rest of the silence and its
    margin (all of it when the last packet's time is unknown), never measured from the
    old reference (issue 25: the resume's first packet a 36,400-count jump)."""
    sent = None if silent_s is None else NOW - silent_s
    c = plan_contact(SILENCE, last(sent_at=sent), "fresh", "x:1", NOW)
    assert c.kind == "fresh" and not c.held.any()
    assert c.wait_s == pytest.approx(wait_s, abs=1e-3) and "2 s of silence" in c.why


@pytest.mark.parametrize("behaviour", [None, KEEP, SILENCE, CLIENT])
def test_a_lost_state_file_of_an_earlier_session_asks(behaviour):
    """A resume whose sidecar records an earlier session but whose state file is missing
    (another $PLANECAL_STATE_DIR, another user) asks in one line naming --rt-fresh and
    --rt-keep; --rt-keep cannot repeat a delta no file holds, so it asks too. --rt-fresh
    is the operator's statement (on a cell fresh after silence: the whole silence waited)."""
    lost = "RUN.tsv.json (an earlier session)"
    for override in (None, "keep"):
        with pytest.raises(InputError) as e:
            plan_contact(behaviour, None, override, "x:1", NOW, lost=lost)
        msg = str(e.value)
        assert "\n" not in msg and msg.startswith(lost) and "--rt-fresh" in msg \
            and "--rt-keep" in msg
    c = plan_contact(behaviour, None, "fresh", "x:1", NOW, lost=lost)
    assert c.kind == "fresh" and c.wait_s == (2.5 if behaviour is SILENCE else 0)
    # no earlier session anywhere: both behaviours agree on 0, nothing to wait for
    assert plan_contact(behaviour, None, None, "x:1", NOW).kind == "either"
