"""Detection: one cloud in, a detection out, and the rules that judge what was found."""
