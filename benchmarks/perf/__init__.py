"""How fast: throughput, compile time, program size and per-step cost of vcjax's closed loops
(each module runs with ``python -m benchmarks NAME``; ``python -m benchmarks`` lists them)."""
