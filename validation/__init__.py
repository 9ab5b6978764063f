"""Validation: block-diagram simulation, scenarios, reproduction of the paper, design comparison,
Monte Carlo campaigns and the extensions study.

Result objects return their report as a content map, ``files() -> {file name: content}``
(text, a JSON document, or a ``matplotlib.figure.Figure``); nothing here writes a report
file or prints. The one exception is a campaign's sample store, which
:func:`ilcdob.validation.campaign.run_campaign` keeps in its folder while it runs so that a
killed campaign resumes.
"""
