"""What a crowd is made of and how it is written down: the configuration and its
validation, config files, controller trees authored as node specs, the show's data,
agent placement, the seat generator and the synthetic characters the tests and
benchmarks use. Above :mod:`..variety`.
"""
