"""A calibration's report.

Its figures (:mod:`calibration.report.figures`), the leave-one-out beside the in-sample
fit, and the summary in Markdown and HTML.
"""
