"""Reference harness for identifying ship manoeuvring models."""

__version__ = "0.1.0"
