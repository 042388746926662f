"""Where each sequence stands: every task's state, derived from its HITs, assignments and QC
reports, and the sequence's current solve (read-only; nothing here changes any stage)."""
