"""Speed and peak memory of hystid's main operations (asv ``time_*`` and ``peakmem_*``).

Each benchmark prepares its workload in ``setup`` (records, models, compiled kernels:
:func:`workloads.make`), so only the operation itself is measured. Compare two commits with
``asv continuous A B`` or ``python benchmarks/compare_commits.py A B`` (ratios in one run).
"""

import workloads


class _Workload:
    """A workload of :data:`workloads.WORKLOADS`, prepared once per benchmark process."""

    timeout = 600
    number = 1
    repeat = (3, 10, 30.0)
    workload = ""

    def setup(self, *args):
        self.run = workloads.make(self.workload)


class Simulate(_Workload):
    workload = "simulate"

    def time_simulate(self):
        self.run()

    def peakmem_simulate(self):
        self.run()


class Identify:
    """Each identification method on the reference stage."""

    timeout = 600
    number = 1
    repeat = (2, 5, 60.0)
    params = ["batch", "online", "eria", "ekf", "pi"]
    param_names = ["method"]

    def setup(self, method):
        self.run = workloads.make(f"identify_{method}")

    def time_identify(self, method):
        self.run()

    def peakmem_identify(self, method):
        self.run()


class OnlineUpdate(_Workload):
    workload = "online_update"

    def time_update_per_sample(self):
        self.run()

    def peakmem_update_per_sample(self):
        self.run()


class OnlinePartialFit(_Workload):
    workload = "online_partial_fit"

    def time_partial_fit(self):
        self.run()


class Diagnose(_Workload):
    workload = "diagnose"
    repeat = (2, 3, 120.0)

    def time_diagnose(self):
        self.run()

    def peakmem_diagnose(self):
        self.run()


class Compensate(_Workload):
    workload = "compensate"

    def time_feedforward(self):
        self.run()

    def peakmem_feedforward(self):
        self.run()


class ClosedLoop(_Workload):
    workload = "closed_loop"

    def time_closed_loop(self):
        self.run()
