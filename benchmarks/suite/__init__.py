"""The side-by-side benchmark suite: workloads, timing harness and one module per framework.

``workloads`` defines sizes, float32 inputs, float64 NumPy references and tolerances
once; ``<framework>_impl`` modules turn a workload into a runner (one step on prepared
data, plus a way to fetch the result). ``bench_cpu.py`` and ``bench_cuda.py``
pick the frameworks, workloads and device and hand them to ``harness``.
"""
