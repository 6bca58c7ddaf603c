"""Documents built from results: the HTML study report and the paper's
reproduction."""
