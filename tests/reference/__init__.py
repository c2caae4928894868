"""Independent reference implementations the tests compare vcjax against: plain NumPy models
written from the equations in the docstrings, not translated from the JAX code
(:mod:`tests.reference.numpy_reference`: Simulation 1's ``vcm_integral`` closed loop;
:mod:`tests.reference.numpy_remus100`: PythonVehicleSimulator's REMUS 100 step). The
benchmarks time vcjax against them (``benchmarks/perf/numpy_baseline.py``,
``benchmarks/perf/numpy_remus100.py``).

Also the helpers the tests and the benchmarks share (:mod:`tests.reference.hlo`: reading a
compiled program's scan body; :mod:`tests.reference.programs`: a loop's programs and their build
costs). The benchmarks import this package; the tests never import ``benchmarks``."""
