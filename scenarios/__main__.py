"""Main job: the paper's two hexapod scenarios with their leg-force chart."""
from .paper_forces import main

main()
