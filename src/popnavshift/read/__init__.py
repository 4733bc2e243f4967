"""The read side: a finished study folder as typed data, without the simulator.

:func:`.folder.open_study` reads a folder once (its tables, manifest and parsed study);
its main part and any part's runs are selected through it; :mod:`.access` is the Python
API (``popnavshift.load``, ``results``, ``cards``). Analysis, report, evaluate and the
audit read through this package; nothing here imports the engine or navground.
"""
