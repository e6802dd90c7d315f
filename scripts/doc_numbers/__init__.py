"""Every number the docs quote that a script can recompute, and the check that reruns them.

* :mod:`scripts.doc_numbers.quotes`: one quoted number (:class:`Quote`), the measurement that
  recomputes it (:class:`Source`), and the comparison of the two;
* :mod:`scripts.doc_numbers.sources`: the measurements (a run of fgslam on a bundled log, a
  simulated run, a script's experiment), each run once however many numbers it feeds;
* :mod:`scripts.doc_numbers.registry`: the quoted numbers of README.md and docs/*.md.

``python -m scripts.check_doc_numbers`` (scripts/check_doc_numbers.py) is the command;
``tests/test_doc_numbers.py`` runs it.
"""
