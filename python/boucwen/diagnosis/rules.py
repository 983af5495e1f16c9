"""Every rule the diagnosis decides by, in one registry, each with its reason.

A rule is one place where the diagnosis chooses: the judge's test and its conditions,
the screen that chooses which moves are fitted, what makes a fit no candidate, how the
search takes a move, and how sure the report says each name is. Each
:class:`~boucwen.diagnosis.judge.Decision` names the rule that decided it
(``Decision.rule``); the list in docs/diagnosis.md is this registry's
:func:`markdown` (``python -m boucwen.diagnosis`` prints it, and a test holds the
docs to it). A stranger counts the rules here, not in the search.

Stages, in the order a move meets them: ``folds`` (where the held-out data lie),
``screen`` (what is fitted), ``candidate`` (what a fit must be to be judged), ``judge``
(the one test), ``search`` (which accepted move is taken), ``report`` (how sure a name
is).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RULES", "Rule", "markdown", "rule"]


@dataclass(frozen=True)
class Rule:
    """One rule of the diagnosis.

    Attributes:
        name: its name, as ``Decision.rule`` gives it.
        stage: ``folds``, ``screen``, ``candidate``, ``judge``, ``search`` or ``report``.
        decides: what it decides, in one sentence.
        reason: why, in one or two (a physical or statistical reason, never a record).
        where: the code that applies it.
    """

    name: str
    stage: str
    decides: str
    reason: str
    where: str


_ALL = (
    Rule(
        "forward_origins",
        "folds",
        "The record is cut at forward origins: the first where the past holds half the record's information "
        "about each unknown, the others evenly in its excitation (half voltage travel, half time) after it.",
        "What a user relies on is prediction of later data; a refit that has not seen the step cannot be "
        "judged on its response, and a rest adds time but no travel.",
        "heldout.Folds.of",
    ),
    Rule(
        "record_part",
        "folds",
        "The held-out error is counted after the record's offset and straight-line trend in time are "
        "re-estimated on its held-out samples together by least squares, alike for both models; a model carried "
        "to another record has that record's offset, trend and initial state re-estimated there, and leaves the "
        "record's own effects behind.",
        "A user carries the device to the next record and re-estimates there what belongs to that record (a "
        "sensor's zero, the day's temperature, a sensor's settling); a gain that lives in the record's trend "
        "does not carry, one that follows the input does. One line per record, as a day has one zero and one "
        "drift: a line per fold would also take what the input drives slowly.",
        "heldout.less_record_part, unseen.carried",
    ),
    Rule(
        "creep_span",
        "candidate",
        "No creep element is slower than the record its fit sees (time constants from 10 samples to the "
        "record's length).",
        "Over a span T an element of time constant much beyond T answers a step by a straight line in time, "
        "which the record's own trend makes as well: the record cannot tell it from the day's drift.",
        "effects.creep.creep_time_constants",
    ),
    Rule(
        "score_level",
        "screen",
        "An add move is fitted only where its score at the current model (the supremum over its grid) has a "
        "p-value at most 20 times the judge's level for the move.",
        "A move the judge accepts on held-out data has a far smaller in-sample p-value; the factor covers what "
        "the score approximates, and a loose screen costs fits, never a decision.",
        "score.Scorer.score",
    ),
    Rule(
        "score_gain",
        "screen",
        "An add move is fitted only where its first-order in-sample gain is at least half the least gain "
        "the judge asks of it.",
        "A converged fit moves further along the effect than its first-order step; half is the margin.",
        "score.Scorer.score",
    ),
    Rule(
        "copy_screen",
        "screen",
        "On a long, fast record every move that passed the score is first fitted on a decimated copy; the "
        "moves the copy ranks best, cannot tell from the best, or sees any gain from are fitted on the record.",
        "The copy holds every effect but a delay and a high mode (fitted on the record directly); it only "
        "chooses what is fitted, the judge decides on the record.",
        "search._chosen_on_copy",
    ),
    Rule(
        "fold_screen_band",
        "screen",
        "A decision read from the first Gauss-Newton step of each fold's refit is confirmed by converged "
        "refits within the band about its threshold, for the move taken, an accepted drop and every move the "
        "record may not tell from the best.",
        "The first step is exact to first order; far from the threshold its error cannot change the verdict "
        "(the band is the largest error measured, with a margin).",
        "search._Round.settle",
    ),
    Rule(
        "not_found",
        "candidate",
        "A fit with the effect that ends worse in-sample than the model without it did not find the effect: "
        "no candidate.",
        "Every effect can be set to change nothing; a fit that ends worse stopped in another basin.",
        "fits.add",
    ),
    Rule(
        "not_in_record",
        "candidate",
        "An effect whose fit changes the prediction of the record by less than a thousandth of the residual's "
        "RMS is not in the record: no candidate.",
        "An effect is named for what it does to the record, not for what it does beyond it.",
        "fits.add",
    ),
    Rule(
        "not_what_its_name_says",
        "candidate",
        "A fitted effect whose values make it something else (a mode without a peak, a clip at a rest level) "
        "is no candidate.",
        "A name is a physical claim; a mode with ζ ≥ 1/√2 is a lag and a clip that holds no moving input is "
        "the offset's.",
        "Effect.rejects, Effect.rejects_on",
    ),
    Rule(
        "bounded",
        "candidate",
        "A fitted model that leaves the record's range on inputs within its limits is no candidate.",
        "Users carry the model to other inputs and into control loops.",
        "fits._valid, boundedness.check_model",
    ),
    Rule(
        "forward_gain",
        "judge",
        "A move is accepted only where its held-out gain's Diebold-Mariano statistic exceeds Student's t at "
        "level α·2⁻ʳ/m (round r, m moves), the variance from the better model's residual dependence.",
        "The rounds spend α/2, α/4, …: the whole search accepts a move that does not improve prediction with "
        "chance at most α.",
        "judge.judge",
    ),
    Rule(
        "least_share",
        "judge",
        "A move is accepted only where it removes at least min_share of the reference's held-out error beyond "
        "the noise.",
        "The base model's form is never exact: on a long record a reshaping of its misfit is significant but "
        "small, and carries to no other record.",
        "judge.judge",
    ),
    Rule(
        "sampling_resolution",
        "judge",
        "A move is accepted only where its gain exceeds the model's own error from stepping at the record's interval.",
        "A device runs in continuous time; a candidate can take up part of the model's stepping error, on "
        "held-out data too.",
        "judge.judge, fits.resolution",
    ),
    Rule(
        "not_judgeable",
        "judge",
        "A gain whose statistic is not finite (no fold's refit converged for both, or both predict alike) "
        "never accepts.",
        "A number that is not a number is no evidence either way.",
        "judge.judge",
    ),
    Rule(
        "converged",
        "judge",
        "A candidate whose whole-record fit did not converge is never accepted.",
        "A decision never reads a fit stopped by a budget: where it stopped is a property of the solver, not "
        "of the record.",
        "search._decide",
    ),
    Rule(
        "drop_earns",
        "judge",
        "An effect is dropped where the current model no longer passes the judge against the model without it.",
        "An effect added early may be made redundant by one added later.",
        "search._decide",
    ),
    Rule(
        "drop_first",
        "search",
        "An accepted drop is taken before any add: of several, the effect that earns least.",
        "A simpler model that predicts no worse is preferred.",
        "search._take",
    ),
    Rule(
        "largest_statistic",
        "search",
        "Of the accepted adds and swaps, the one of largest statistic that no other beats in a direct "
        "comparison leads the round.",
        "The move that predicts unseen data best, by the same test.",
        "search._Round.best",
    ),
    Rule(
        "fewest_unknowns",
        "search",
        "Within the leading move's ambiguity set (converged candidates it does not tell apart, on a comparison "
        "the record could make) the model takes the accepted member with the fewest unknowns, then the largest "
        "statistic; the others are its rivals.",
        "The one-standard-error rule: prefer the simplest model not clearly worse (Breiman et al. 1984).",
        "search._take",
    ),
    Rule(
        "structure_waits",
        "search",
        "The other structure (the hysteretic oscillator) is taken only while no input-driven move is accepted.",
        "It ends the search, so it is compared with the input-driven model at its best.",
        "search._Round.best",
    ),
    Rule(
        "quiet_residual",
        "search",
        "Where the residual is consistent with the noise a round proposes only drops and the other structure.",
        "Nothing is left to add; an effect added early may still be redundant.",
        "search.search",
    ),
    Rule(
        "never_revisit",
        "search",
        "A model the search has held is never proposed again.",
        "Floating selection must not cycle.",
        "search.search",
    ),
    Rule(
        "confident_share",
        "report",
        "A name is confident only where it has no rival, its fit converged, and the model removes at least "
        "confident_share of the base model's error beyond the noise (or leaves only noise).",
        "Effects that leave much may stand in for something outside the vocabulary.",
        "outcome.named",
    ),
)

#: The rules by name.
RULES: dict[str, Rule] = {r.name: r for r in _ALL}


def rule(name: str) -> Rule:
    """The rule ``name``; KeyError naming it where there is none."""
    try:
        return RULES[name]
    except KeyError:
        raise KeyError(f"no rule {name!r} in the diagnosis's registry") from None


def markdown() -> str:
    """The registry as the markdown table docs/diagnosis.md holds."""
    lines = ["| stage | rule | what it decides | why | where |", "|---|---|---|---|---|"]
    lines += [f"| {r.stage} | `{r.name}` | {r.decides} | {r.reason} | `{r.where}` |" for r in _ALL]
    return "\n".join(lines)
