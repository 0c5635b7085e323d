"""Independent truth for the tests, demos and benchmarks of ``subdomain_contact``.

``analytic``: closed-form solutions; ``cases``: ready-made scenes and problems with their closed
forms (the ``.geo`` files of the repository's ``geo/`` folder); ``nodal``: nodal errors
against a reference, reduced over all ranks. Not part of the library: it reads the repository.
"""
