"""Object categories of the synthetic generator and the benchmarks (the ArtGS paper's seven)."""

CATEGORIES = ("dishwasher", "refrigerator", "oven", "microwave", "storage", "drawer", "cabinet")
