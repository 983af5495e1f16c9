"""How sure the diagnosis is of each name (boucwen.diagnosis.confidence), on constructed evidence."""

from boucwen.diagnosis.confidence import confidence


def _trial(gain, folds=(0.2, 0.2, 0.2, 0.2)):
    return {"gain_over_null": gain, "fold_gains": list(folds), "local_gain": gain, "noise_share": 0.5}


def _evidence(trials, kept="input_lag", lookalike=None, calls=()):
    round_ = {"kept": True, "most_likely": kept, "trials": trials, "lookalike": lookalike or {}}
    return {"rounds": [round_], "close_calls": list(calls)}


def earns(trial):
    return trial["gain_over_null"] >= 0.1


def test_an_effect_alone_in_explaining_the_record_on_every_fold_is_confident():
    ev = _evidence({"input_lag": _trial(0.3), "creep": _trial(0.02)})
    got = confidence(["input_lag"], ev, 0.01, earns=earns)["input_lag"]
    assert got["level"] == "confident" and got["competing"] is None


def test_another_effect_that_also_earned_makes_it_tentative_and_is_named():
    ev = _evidence({"input_lag": _trial(0.28), "creep": _trial(0.27), "drift": _trial(0.05)})
    got = confidence(["input_lag"], ev, 0.01, earns=earns)["input_lag"]
    assert got["level"] == "tentative" and got["competing"] == "creep"


def test_a_look_alike_test_that_named_it_separates_the_two():
    ev = _evidence(
        {"drift": _trial(0.3), "creep": _trial(0.2)},
        kept="drift",
        lookalike={"follows": {"follows": "drift"}, "phase": {"shape": "none"}},
    )
    assert confidence(["drift"], ev, 0.01, earns=earns)["drift"]["level"] == "confident"


def test_a_fold_without_gain_a_close_call_or_a_small_explained_share_make_it_tentative():
    ev = _evidence({"input_lag": _trial(0.3, folds=(0.3, 0.2, -0.01, 0.1))})
    assert "every fold" in confidence(["input_lag"], ev, 0.01, earns=earns)["input_lag"]["why"]
    call = {"decision": "input_lag: earns", "value": 0.1, "against": 0.1, "chose": "no", "kind": "answer"}
    ev = _evidence({"input_lag": _trial(0.3)}, calls=[call])
    assert "close call" in confidence(["input_lag"], ev, 0.01, earns=earns)["input_lag"]["why"]
    ev = _evidence({"input_lag": _trial(0.3)})
    assert confidence(["input_lag"], ev, 0.01, explained=0.6, earns=earns)["input_lag"]["level"] == "tentative"
