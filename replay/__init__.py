"""``dagsreplay``: re-runs pipeline stages from recorded logs.

This package depends on the core package ``dynactivegs``; the core never imports it.
"""
