"""The application: the ``ilcdob`` command and its use cases.

* :mod:`.commands` - every command as a plain function (also for scripts and notebooks);
* :mod:`.output` - the one results writer (folders written as a unit, ``manifest.json``);
* :mod:`.html` - the self-contained HTML report, rendered from result files only;
* :mod:`.console` - progress bars, notes, summaries and error lines;
* :mod:`.options` - every command and option of the command line, as data;
* :mod:`.cli` - argument parsing (built from :mod:`.options`) and exit codes.

This layer may import every other; nothing imports it (``tests/test_layout.py``).
"""
