"""The hybrid loop: smooth phases integrated between located events, the transitions at events, the
step budget and the progress line, a mode on the one pipeline as the loop runs it."""
