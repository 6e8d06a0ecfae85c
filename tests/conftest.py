"""Test-session set-up shared by every test directory."""

import scipctl  # noqa: F401  (first, so that its BLAS thread default applies before numpy loads, as in the CLI)
