"""A step's batches of candidates: a batch boundary never splits candidates the screening could not tell apart."""

from analysis.gap.ranking import MAX_TRIED, _next_batch
from analysis.gap.results import Screened


def _screened(improvements):
    return [Screened(name, 0.0, {}, imp, 10.0, True) for name, imp in improvements.items()]


def test_a_candidate_tied_at_screening_with_the_last_of_a_batch_joins_it():
    # seed 205000103's first step, rounded: the sensor spring's improvement equalled the base spring's, fifth
    improvements = {"hysteresis": 29.4, "pzt_modulus": 26.3, "width_loss": 26.1, "base_compliance": 25.3,
                    "sensor_compliance": 25.3, "cf_thickness": 14.9}
    queue = list(improvements)
    batch, rest = _next_batch(queue, _screened(improvements), bar=8.6)
    assert batch == queue[:5] and rest == ["cf_thickness"]
    # the same queue with the ties far apart keeps the plain batch size
    spaced = dict(zip(queue, (60.0, 50.0, 40.0, 30.0, 20.0, 10.0), strict=True))
    batch, rest = _next_batch(queue, _screened(spaced), bar=8.6)
    assert len(batch) == MAX_TRIED and rest == queue[MAX_TRIED:]


def test_an_empty_or_short_queue_is_one_batch():
    assert _next_batch([], [], bar=5.0) == ([], [])
    improvements = {"creep": 40.0, "hysteresis": 12.0}
    assert _next_batch(list(improvements), _screened(improvements), bar=5.0) == (["creep", "hysteresis"], [])
