import pytest
import torch

from unps.errors import InputError
from unps.threads import available_cpus, parallel_jobs, set_fit_threads, share


def test_the_cpus_are_shared_between_parallel_fits():
    assert share(2, 1) == 2 and share(2, 2) == 1 and share(16, 3) == 5 and share(2, 8) == 1
    assert parallel_jobs(None, 8) == 1
    assert parallel_jobs({"n_jobs": 4, "backend": "loky"}, 8) == 4
    assert parallel_jobs({"n_jobs": -1}, 8) == 8          # joblib: one job per CPU
    assert parallel_jobs({"partition": "gpu"}, 8) == 1    # submitit: one job per allocation


@pytest.fixture
def restore_threads():
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


def test_fit_threads_come_from_the_option_then_the_environment_then_the_share(monkeypatch, restore_threads):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert set_fit_threads(1, {"n_jobs": 2}) == (1, "threads=") and torch.get_num_threads() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert set_fit_threads(None, None) == (3, "OMP_NUM_THREADS")
    monkeypatch.delenv("OMP_NUM_THREADS")
    threads, source = set_fit_threads(None, {"n_jobs": 2})
    assert threads == max(available_cpus() // 2, 1) == torch.get_num_threads()
    assert "CPUs" in source


def test_a_thread_count_below_one_is_refused(restore_threads):
    with pytest.raises(InputError, match="threads must be a whole number >= 1"):
        set_fit_threads(0, None)
