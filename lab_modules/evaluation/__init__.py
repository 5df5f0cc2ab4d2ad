"""Headless evaluation of any exercise: what the lab measures about an exercise without
drawing it: its claims measured per seed (``measured_claims``), its pole sets with their
declared categories, numbered modes and physical names (``poles``), root loci
(``root_locus``), loop margins (``margins``) and each panel's results remembered per setting
(``panel_analyses``).  Above ``exercises``, below the app: pure
data objects that ``app/panels`` draws and ``app/commands`` prints."""
