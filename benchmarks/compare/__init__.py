"""Git A/B comparisons: an older revision's ``vcjax/`` extracted into a temporary folder and
timed against this checkout in alternating fresh processes."""
