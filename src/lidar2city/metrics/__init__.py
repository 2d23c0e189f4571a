"""Quality measures: ISPRS filter errors, classification scores, footprint overlap,
pixel accuracy, model fit and corner accuracy. Import the submodule you need."""
