"""The package's version, in a leaf module: the library reads it from here, never from the
root package (whose import would run ``mrfpe/__init__.py`` from inside its submodules)."""

__version__ = "0.1.0"
