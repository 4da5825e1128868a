"""The run report: HTML/Markdown, tables, figures."""
