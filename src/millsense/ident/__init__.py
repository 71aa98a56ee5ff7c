"""System identification: from recordings to the models the estimators need."""
