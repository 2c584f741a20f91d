"""``ros-isolated-test report``: what a tree of result files says, as text and as a page.

Above ``xunit``, which reads, makes canonical and writes one file: here the many files
of a run (or of several machines' runs) are found and read one at a time (``tree``),
counted so every count adds up (``counts``), printed as colcon's lines or JSON
(``text_report``) and drawn as one self-contained page (``html_report`` reads each file
into it, ``bounded_values`` reads each value it draws within bounds, ``html_timeline``
draws its bars, ``html_parts`` its case blocks, ``html_page`` puts it together,
``html_assets`` is its style and script). Whatever is said after every file is read
waits on disk (``spool``), so memory does not grow with the tree or its failures.
"""
