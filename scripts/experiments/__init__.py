"""One-off experiments kept because the docs quote their numbers: each runnable as
``python -m scripts.experiments.NAME`` from the repository's root. README.md in this folder
says, per experiment (kept or deleted), the question, the answer and where the docs record it."""
