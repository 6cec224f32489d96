"""usd_export: OpenUSD scenes with repaired glass and mirror geometry and spatial audio (issue 6)."""
