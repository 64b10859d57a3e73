"""What a person reads about an identification, shared by the `shakeid` command and the HTTP service.

    identification.py  the identification report: a folder with index.html, figures like the paper's,
                       the coefficient table and the model JSON
    explain.py         the discrepancy report of `shakeid explain`: a folder with its own index.html
    text.py            the same results as plain text: the coefficient table and the terminal summary
    html.py            the small HTML pieces both reports are built from (tables, figures with captions)

This package sits between the numerics and their users: it may import identify (and numpy/matplotlib),
never daq, server or the CLI package shakeid (tests/test_layers.py).
"""
