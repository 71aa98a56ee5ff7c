from millsense.cli.main import main

main()
