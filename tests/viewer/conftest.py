"""The viewer's tests share tests/conftest.py's fixtures (the tracked installation: `archived`)."""
