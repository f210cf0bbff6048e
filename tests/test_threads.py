"""A scan's matrix products run on one BLAS thread, and the caller's setting comes back afterwards."""

import numpy as np
from threadpoolctl import threadpool_info

from measurement import threads


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_blas_thread_inside_and_the_previous_count_after():
    np.ones((4, 4)) @ np.ones((4, 4))  # NumPy's BLAS is loaded
    before = _blas_threads()
    assert before
    with threads.one_blas_thread():
        assert set(_blas_threads()) == {1}
    assert _blas_threads() == before


def test_a_scan_runs_its_products_on_one_thread(monkeypatch, small_capture):
    from measurement import pipeline
    from measurement.calibration import load_calibration
    from measurement.images import read_image

    seen = []
    real = pipeline.label_centres

    def spy(*args, **kwargs):
        seen.append(set(_blas_threads()))
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "label_centres", spy)
    cal = load_calibration(small_capture / "truth" / "truth.json")
    pipeline.scan(read_image(small_capture / "scan" / "side.png"), cal, "side")
    assert seen == [{1}]


def test_a_child_forked_after_a_scan_starts_its_own_threads():
    import multiprocessing

    from measurement.detection import detect_centres

    rng = np.random.default_rng(3)
    image = (rng.random((600, 400)) * 20).astype(np.uint8)
    image[:, 100::40] = 200  # ten bright columns: stripes in every band of rows
    parent = len(detect_centres(image))
    assert parent > 0 and threads.second_core().submit(lambda: 1).result() == 1  # both pools have threads

    def child(queue):
        queue.put((len(detect_centres(image)), threads.second_core().submit(lambda: 2).result()))

    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=child, args=(queue,))
    proc.start()
    proc.join(60)
    assert proc.exitcode == 0
    assert queue.get(timeout=5) == (parent, 2)


def test_work_handed_to_the_second_core_from_the_second_core_runs_there_at_once():
    core = threads.second_core()

    def outer():
        inner = core.submit(lambda: threading.current_thread().name)
        return threading.current_thread().name, inner.result(timeout=5)

    import threading

    outer_name, inner_name = core.submit(outer).result(timeout=10)
    assert outer_name == inner_name and outer_name.startswith("bodyscan-second")
    failing = core.submit(lambda: core.submit(lambda: 1 / 0).exception(timeout=5))
    assert isinstance(failing.result(timeout=10), ZeroDivisionError)


def test_scans_overlapping_in_threads_leave_the_blas_threads_as_they_found_them():
    import threading

    np.ones((4, 4)) @ np.ones((4, 4))
    before = _blas_threads()
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def first():
        with threads.one_blas_thread():
            first_in.set()
            second_in.wait(5)
        first_out.set()

    def second():
        first_in.wait(5)
        with threads.one_blas_thread():
            second_in.set()
            first_out.wait(5)
            seen["after the first left"] = set(_blas_threads())  # the second is still inside

    workers = [threading.Thread(target=first), threading.Thread(target=second)]
    for w in workers:
        w.start()
    for w in workers:
        w.join(10)
    assert seen["after the first left"] == {1}
    assert _blas_threads() == before
