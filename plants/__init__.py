"""Plant models: the systems the observers are tested on."""
