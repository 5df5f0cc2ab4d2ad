"""Headless evaluation of any exercise: what the lab measures about an exercise without
drawing it (its claims measured per seed; pole sets and their categories, modes and
their physical names, root loci, loop margins).  Above ``exercises``, below the app:
pure data objects that ``app/panels`` draws and ``app/commands`` prints."""
