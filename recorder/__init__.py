"""The live-run harness behind ``dagsrun``: runs the simulator and the pipeline, writes outputs.

This package depends on the core package ``dynactivegs``; the core never imports it.
"""
