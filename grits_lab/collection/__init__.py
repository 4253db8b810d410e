"""Dataset collection jobs: scripted demonstrations and perturbed spillage trials, run on the runners.

Each job plans picklable episode specs, hands the runner its work function (`demo_episode`,
`spillage_trial`) and writes the results through `grits_lab.data.format` (the storage layer).
"""
