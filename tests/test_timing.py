import time

from unps.timing import Span, recording, stage


@stage("decorated")
def nap():
    time.sleep(0.01)


def test_stages_add_up_nest_and_reach_every_open_recording():
    with recording() as outer:
        with stage("outer"):
            with recording() as inner:
                nap()
                nap()
        span = Span("span")
        span.start()
        time.sleep(0.01)
        span.stop()
    assert inner.keys() == {"decorated"} and 0.02 <= inner["decorated"] < 1
    assert outer["decorated"] == inner["decorated"] and outer["outer"] >= outer["decorated"]
    assert outer["span"] >= 0.01


def test_nothing_is_recorded_without_a_recording():
    nap()
    span = Span("span")
    span.start()
    span.stop()
    with recording() as seconds:
        pass
    assert seconds == {}
