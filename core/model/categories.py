"""Object categories of the synthetic generator and the benchmarks (the ArtGS paper's seven)."""

CATEGORIES = ("dishwasher", "refrigerator", "oven", "microwave", "storage", "drawer", "cabinet")

#: Kinds beyond the seven that the synthetic generator draws in regimes with variety.
EXTRA_KINDS = ("door", "washing_machine", "chest")

#: Everything the generator makes: the seven categories, then kinds drawn only with variety.
KINDS = CATEGORIES + EXTRA_KINDS
