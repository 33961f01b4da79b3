"""The report (`r2s report`): statistics of a programs dataset (stats), its plots (plots), the optional scenario
mining section (query_section), arranged into one document printed as Markdown and HTML (document)."""
