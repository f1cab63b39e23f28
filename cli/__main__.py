"""``python -m cli`` runs the sonarmap command line."""

from cli.app import main

main()
