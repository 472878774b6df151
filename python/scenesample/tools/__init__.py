"""The package's tools, beside its methods: the benchmarks (``python -m scenesample.bench``),
the demo (``python -m scenesample.demo``), the gallery (``python -m scenesample.gallery``) and
the papers' experiments (``python -m scenesample.experiments``). They use the public API; the
methods never import them."""
